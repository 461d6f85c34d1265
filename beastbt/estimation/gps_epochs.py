"""One GPS fix per measurement epoch, for the estimator.

A receiver that sends GGA and RMC (the MTK3339 does, with GSA between) gives
the NMEA driver two positions per epoch with the same UTC time: the same
measurement twice. Fusing both would count it twice and make the filter
twice as confident as it should be. :class:`EpochFilter` passes one fix per
epoch: of the fixes that arrive together it keeps the last one, which on an
MTK3339 is the RMC (it carries what GGA said too: quality, HDOP and altitude
of the epoch, plus speed and course); a fix of an epoch already passed on
(the second half of an epoch split across two polls) is dropped.

This is the choice made instead of ``position_sentences: [GGA]`` in the
profile: GGA carries no course over ground, which the EKF uses as a heading
measurement while moving.
"""

from __future__ import annotations

from typing import Optional, Sequence

from beastbt.blackboard.types import GpsFix


class EpochFilter:
    """Keeps one :class:`GpsFix` per epoch (same ``time_utc``), the last of those that arrive together.

    Fixes without a UTC time (the date is not known yet) belong to the epoch
    of the fix that follows them in the same poll.
    """

    def __init__(self) -> None:
        self._last_time: Optional[str] = None
        self.dropped = 0
        """How many duplicate fixes were held back (the second sentence of an epoch)."""

    def __call__(self, fixes: Sequence[GpsFix]) -> list[GpsFix]:
        """The fixes of one poll, one per epoch, oldest first."""
        out: list[GpsFix] = []
        for fix in fixes:
            if fix.time_utc is not None and fix.time_utc == self._last_time:
                self.dropped += 1  # the rest of an epoch that went to the estimator in an earlier poll
                continue
            if out and (out[-1].time_utc == fix.time_utc or out[-1].time_utc is None):
                # Same epoch (a fix without a date is the GGA before the epoch's first RMC):
                # the later sentence carries what the earlier one said.
                out[-1] = fix
                self.dropped += 1
            else:
                out.append(fix)
        if out:
            self._last_time = out[-1].time_utc
        return out
