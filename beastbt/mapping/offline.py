"""Building a map from a recorded run (``beastbt map build RUN``): the same mapper as online, fed afterwards.

A run's recording is read by the ``map`` command (the recording layer sits
above this one); what it hands here is the run's messages in recorded order,
as ``("odom", (stamp_s, x, y, yaw, yaw_rate_rps))`` for every tick's
dead-reckoned pose and ``("scan", LaserScan)`` for every LiDAR revolution.
They are fed to :class:`~beastbt.mapping.slam.OnlineMapper` as the online part
feeds them tick by tick (a tick's scan is recorded before its pose: it is held
until that pose is in), so a run gives the same kind of map online and
offline.
"""

from __future__ import annotations

from typing import Any, Iterable, Optional

from beastbt.mapping.slam import MappingConfig, OnlineMapper

NO_SCANS_HINT = ("record the run's sensors (beastbt run ... --record-sensors), or build the map while the run goes on "
                 "(beastbt run ... --build-map maps/office.yaml)")
"""What to do about a recording without scans."""


def feed(mapper: OnlineMapper, messages: Iterable[tuple[str, Any]]) -> OnlineMapper:
    """Feed ``messages`` (``("odom", (stamp_s, x, y, yaw, yaw_rate_rps))`` or ``("scan", LaserScan)``, in recorded
    order) to ``mapper``; the mapper."""
    pending = []
    for kind, value in messages:
        if kind == "odom":
            mapper.add_odom(*value)
            for scan in pending:
                mapper.add_scan(scan.stamp_s, scan.angles_rad, scan.ranges_m, scan.scan_time_s)
            pending.clear()
        elif kind == "scan":
            pending.append(value)
    for scan in pending:
        mapper.add_scan(scan.stamp_s, scan.angles_rad, scan.ranges_m, scan.scan_time_s)
    return mapper


def build_offline(messages: Iterable[tuple[str, Any]], sensor_xy: tuple[float, float], sensor_yaw_rad: float,
                  config: Optional[MappingConfig] = None) -> OnlineMapper:
    """A new mapper for a LiDAR mounted at ``sensor_xy`` (m) / ``sensor_yaw_rad`` on base_link, fed ``messages``
    (see :func:`feed`)."""
    return feed(OnlineMapper(config, sensor_xy, sensor_yaw_rad), messages)


__all__ = ["feed", "build_offline", "NO_SCANS_HINT"]
