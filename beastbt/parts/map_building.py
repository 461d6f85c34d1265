"""Building a map while a run goes on (``beastbt run MISSION --build-map maps/office.yaml``).

The part feeds every tick's dead-reckoned pose (``pose_odom``) and every new
LiDAR revolution (``scan``) to an :class:`~beastbt.mapping.slam.OnlineMapper`
and, when the run ends for whatever reason (success, failure, Ctrl-C, an
internal error), optimises the pose graph once more and writes the map in
``map_server`` format (the YAML and a PGM beside it), saying where in an event
(``map``) and in the summary (``map``).

Where the work is done:

* on the simulator, in the tick itself: a run is deterministic for its seed,
  and at ``--speed max`` there is no real time to keep;
* on the robot, in a worker thread fed through a bounded queue, so that a
  scan match or a graph optimisation never delays a tick; when the worker
  falls behind, whole scans are dropped (counted in the summary) rather than
  the queue growing.

A robot without a LiDAR cannot build a map: the run is refused before
anything moves (exit 2).
"""

from __future__ import annotations

import math
import queue
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional

from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.robot.part import Build, Part

if TYPE_CHECKING:
    from beastbt.mapping.slam import OnlineMapper
    from beastbt.run.runner import MissionRun
    from beastbt.run.session import Prepared

QUEUE_ITEMS = 256
"""The worker's queue (on the robot): about 12 s of poses at 20 Hz, or fewer with scans."""


def no_lidar_problem(profile: Any) -> InvalidInput:
    """The error for ``--build-map`` on a robot profile without a ``lidar:`` section."""
    file = str(profile.file or profile.name)
    return InvalidInput([Problem(file, Position(1, 1), "--build-map needs a LiDAR, and this robot profile has no "
                                 "'lidar:' section", "add the robot's LiDAR (lidar: {type: ld19, port: ...}) to the "
                                 "profile, or run without --build-map")])


class MapBuildingPart(Part):
    """``--build-map FILE``: SLAM from the LiDAR and odometry while the run goes on; the map written at its end."""

    name = "map_building"
    reads = ("scan", "pose_odom")

    def __init__(self) -> None:
        self.path: Optional[Path] = None
        self.mapper: Optional["OnlineMapper"] = None
        self.events: Any = None
        self.written: Optional[dict] = None
        self._last_scan: Any = None
        self._queue: Optional[queue.Queue] = None
        self._worker: Optional[threading.Thread] = None
        self.dropped = 0
        self.failed: Optional[str] = None

    def attach(self, build: Build) -> None:
        """Refuse a robot without a LiDAR, before anything moves."""
        if build.profile.section("lidar") is None:
            raise no_lidar_problem(build.profile)

    def install(self, prepared: "Prepared") -> None:
        """The mapper, on the LiDAR's mounting; on the robot, its worker thread."""
        from beastbt.core.clock import SimClock
        from beastbt.devices.lidar_scan import LidarConfig
        from beastbt.mapping.slam import MappingConfig, OnlineMapper
        from beastbt.robot.profile import section_config

        options = prepared.options
        assert options.build_map is not None
        self.path = Path(options.build_map)
        mounting = section_config(prepared.profile, "lidar", LidarConfig).mounting
        config = MappingConfig(resolution_m=options.map_resolution_m or MappingConfig.resolution_m)
        self.mapper = OnlineMapper(config, (mounting.x_m, mounting.y_m), math.radians(mounting.yaw_deg))
        self.events = prepared.events
        if not isinstance(prepared.clock, SimClock):
            self._queue = queue.Queue(maxsize=QUEUE_ITEMS)
            self._worker = threading.Thread(target=self._work, name="map_building", daemon=True)
            self._worker.start()

    def tick(self, run: "MissionRun", now_s: float) -> None:
        """Hand this tick's odometry pose and a new scan to the mapper (or its worker)."""
        pose = run.bb.pose_odom
        items = []
        if pose is not None:
            items.append(("odom", (pose.stamp_s, pose.x, pose.y, pose.yaw, pose.yaw_rate_rps)))
        scan = run.latest_scan()
        if scan is not None and scan is not self._last_scan:
            self._last_scan = scan
            items.append(("scan", (scan.stamp_s, scan.angles_rad, scan.ranges_m, scan.scan_time_s)))
        for item in items:
            if self._queue is None:
                self._feed(item)
            else:
                try:
                    self._queue.put_nowait(item)
                except queue.Full:
                    self.dropped += item[0] == "scan"

    def _feed(self, item: tuple[str, tuple]) -> None:
        assert self.mapper is not None
        kind, args = item
        if kind == "odom":
            self.mapper.add_odom(*args)
        else:
            self.mapper.add_scan(*args)

    def _work(self) -> None:
        """The worker's loop (robot only): feed the mapper until the sentinel None."""
        assert self._queue is not None
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                self._feed(item)
            except Exception as exc:  # a mapping bug must not pass silently, nor touch the run
                self.failed = repr(exc)

    def close(self) -> None:
        """Finish the work queued, optimise and write the map; say where (event ``map``)."""
        if self._worker is not None and self._queue is not None:
            self._queue.put(None)
            self._worker.join()
        try:
            self.written = self.save()
        except (OSError, ValueError) as exc:  # a full disk, a folder that cannot be made: said, not swallowed
            self.failed = f"cannot write the map to {self.path}: {exc}"
            self.events.add("map", self.failed)

    def save(self) -> Optional[dict]:
        """Optimise and write the map to the ``--build-map`` file; what was written (None without keyframes)."""
        from beastbt.mapping.occupancy_map import save_map
        from beastbt.mapping.slam import MIN_KEYFRAME_RETURNS

        assert self.mapper is not None and self.path is not None
        mapper = self.mapper
        if not mapper.keyframes:
            why = (f"no keyframe: {mapper.stats.scans} LiDAR scans, none with {MIN_KEYFRAME_RETURNS} returns or more "
                   f"while the odometry was known (nothing within the LiDAR's range?)" if mapper.stats.scans
                   else "no LiDAR scan was taken")
            self.failed = why
            self.events.add("map", f"no map written to {self.path}: {why}")
            return None
        mapper.optimise()
        grid = mapper.occupancy_map()
        assert grid is not None
        yaml_path, image_path = save_map(grid, self.path)
        s = mapper.stats
        self.events.add("map", f"map written to {yaml_path} ({grid.cols} x {grid.rows} cells at "
                               f"{grid.resolution_m * 100:g} cm; {s.keyframes} keyframes, {s.loops_closed} loop "
                               f"closures)")
        return {"file": str(yaml_path), "image": str(image_path), "resolution_m": grid.resolution_m,
                "width_m": round(grid.width_m, 3), "height_m": round(grid.height_m, 3)}

    def summarise(self, run: "MissionRun", summary: dict) -> None:
        """``map``: the file written, the keyframes and loop closures, scans dropped by a busy worker."""
        if self.mapper is None:
            return
        s = self.mapper.stats
        entry = dict(self.written or {"file": None})
        entry.update({"scans": s.scans, "keyframes": s.keyframes, "matched": s.matched,
                      "loops_tried": s.loops_tried, "loops_closed": s.loops_closed, "scans_dropped": self.dropped})
        if self.failed:
            entry["error"] = self.failed
        summary["map"] = entry


__all__ = ["MapBuildingPart", "no_lidar_problem", "QUEUE_ITEMS"]
