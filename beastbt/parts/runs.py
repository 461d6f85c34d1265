"""Keeping the disk: a recorded run prunes the oldest finished runs by the profile's ``runs:`` when it starts."""

from __future__ import annotations

from beastbt.robot.part import Part
from beastbt.run.retention import RunsPolicy, prune_runs
from beastbt.run.session import Prepared


def runs_policy(prepared: Prepared) -> RunsPolicy:
    """The run's policy: the profile's ``runs:``, with ``--keep-runs`` (``RunOptions.keep_runs``) over its keep."""
    return RunsPolicy.from_section(prepared.profile.section("runs"), prepared.options.keep_runs)


class RunsRetentionPart(Part):
    """Prunes the runs folder when a recorded run starts (oldest finished runs first; never a running or a kept
    one), each prune an event ``runs_pruned``; and says when the floor cannot be kept."""

    name = "runs"
    section = "runs"
    schema = "parts/runs.schema.json"
    reads = ()

    def install(self, prepared: Prepared) -> None:
        """Prune now, the new run's own folder spared."""
        folder = prepared.folder
        if folder is None:
            return
        policy = runs_policy(prepared)
        events = prepared.events
        runs_dir = folder.path.parent
        try:
            pruned = prune_runs(runs_dir, policy, current=folder.path)
        except OSError as exc:  # the runs folder unreadable: the run is recorded all the same
            events.add("runs_pruned", f"could not prune {runs_dir}: {exc.strerror or exc}")
            return
        if pruned:
            mb = sum(p.size_bytes for p in pruned) / 1e6
            reasons = sorted({p.reason for p in pruned})
            events.add("runs_pruned", f"pruned {len(pruned)} old run(s) in {runs_dir} ({mb:.1f} MB): "
                                      f"{'; '.join(reasons)} (see {runs_dir}/prune.log)")


__all__ = ["RunsRetentionPart", "runs_policy"]
