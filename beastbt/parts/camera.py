"""The camera (the profile's ``camera:``) and the line detector on its frames, on the robot or simulated.

On the robot the camera is read on V4L2 in a thread of its own, from when
the run enables it (a mission that uses the camera, the video stream); on
the simulator a
:class:`~beastbt.sim.camera_emulator.SimCamera` renders the world's
``floor:`` (or a plain floor) through the profile's mounting and the gimbal's
true pan/tilt, with the world's walls and obstacles standing up, a ground
texture where the world has no ``floor:`` (grass outdoors, tiles within walls)
and the world's ``camera:`` effects (:mod:`beastbt.sim.scenery`), behind the same
:class:`~beastbt.devices.camera.Camera` driver. Either way the profile's line
detector runs on the frames (:class:`~beastbt.vision.camera_pipeline.CameraPipeline`,
``io.sensors['camera']``) and the robot gets the ``camera`` capability.

Simulated rendering is lazy: nothing is drawn (and the floor raster is not
even built) until the pipeline is enabled, which the run does when the
mission uses the camera or video is streamed
(:mod:`beastbt.parts.line_following`). On ``RobotIO``: ``camera`` (the
pipeline), ``sim_camera`` (the emulator, once built: tests unplug it),
``floor_map`` (a function returning the :class:`~beastbt.sim.floor.FloorMap`).
"""

from __future__ import annotations

import json
from functools import lru_cache
from typing import Any, Callable, Optional

import numpy as np

from beastbt.core.clock import Clock
from beastbt.core.errors import InvalidInput
from beastbt.core.events import EventLog
from beastbt.devices.camera import Camera, CameraConfig, camera_backend, open_video_capture
from beastbt.robot.part import REAL, SIM, Build, Part
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO
from beastbt.sim.camera_emulator import CameraEffects, SimCamera, SimMjpegCamera
from beastbt.sim.cpu_account import CAMERA, SIM_CPU
from beastbt.sim.floor import FloorMap
from beastbt.sim.scenery import Scenery
from beastbt.sim.robot import Simulator, world_problem
from beastbt.vision.camera_pipeline import CameraPipeline
from beastbt.vision.line_detector import LineDetectorConfig


PLAIN_FLOOR = {"margin_m": 1.0, "background": {"colour": 190, "texture": 8, "texture_scale_m": 0.02}}
"""The floor of a world without ``floor:``: plain light grey (beyond the raster the camera sees its colour)."""


FLOOR_CACHE_SIZE = 4
"""Floor rasters kept per process (about 5 MB each): repeated runs of one world and seed reuse them."""


@lru_cache(maxsize=FLOOR_CACHE_SIZE)
def _floor_cached(floor_json: str, seed: int) -> FloorMap:
    return FloorMap.from_dict(json.loads(floor_json), np.random.default_rng(seed))


def build_floor(floor: dict, seed: int) -> FloorMap:
    """The :class:`FloorMap` of a world's ``floor:`` mapping with texture seed ``seed`` (cached: treat it as read-only)."""
    return _floor_cached(json.dumps(floor, sort_keys=True), int(seed))


def _check_h264(profile: RobotProfile, config: CameraConfig, simulated: bool) -> None:
    """``camera.format: h264`` where it cannot work is an error at that key, before anything moves."""
    from beastbt.devices.camera import h264_problem
    why = h264_problem(config, simulated)
    if why is not None:
        raise InvalidInput([profile.doc.problem(("camera", "format"), f"camera.format: {why}",
                                                "pip install 'beastbt[video]' (PyAV), or use format mjpeg")])


OPENCV_THREADS = 1
"""OpenCV threads in a process that has a camera: one. Its worker pool spins between calls, and on frames this
size (320x240 at 15 fps) the spinning costs more CPU than the split work saves: a warp and a JPEG encode took
2.5 times the process's CPU with the default pool (two threads here) than with one. Every watt counts on a
battery; the frames are not late for it (a few ms each)."""


def one_opencv_thread() -> None:
    """Run this process's OpenCV calls on the calling thread (:data:`OPENCV_THREADS`)."""
    import cv2
    cv2.setNumThreads(OPENCV_THREADS)


def attach_camera(profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog) -> None:
    """The profile's camera on V4L2, read and run through the line detector in a thread (``io.sensors['camera']``)."""
    if profile.section("camera") is None:
        return
    one_opencv_thread()
    config: CameraConfig = section_config(profile, "camera", CameraConfig)
    detector_config: LineDetectorConfig = section_config(profile, "line_detector", LineDetectorConfig)
    sink = events.sink("camera")
    _check_h264(profile, config, simulated=False)

    def make_camera() -> Camera:
        return Camera(lambda: open_video_capture(config), clock, sink, config)

    pipeline = CameraPipeline(make_camera, config, detector_config, sink)
    try:
        pipeline.check()
    except ValueError as exc:
        raise InvalidInput([profile.doc.problem(("camera",), f"in 'camera': {exc}",
                                                "lower the camera's pitch_deg or raise line_detector.roi_far_m")]) from None
    # On the robot the camera is read in a thread of its own, started when the run enables it (a mission
    # that uses the camera, the video stream): a mission that never looks costs no capture and no detection.
    pipeline.threaded = True
    backend = camera_backend(config)
    where = "the Pi camera (libcamera)" if backend == "picamera2" else str(config.device)
    events.add("camera_backend", f"camera: {where} read through {backend}")
    io.sensors["camera"] = pipeline.poll
    io.capabilities.add("camera")
    io.camera = pipeline
    io.closers.append(pipeline.close)


def attach_sim_camera(sim: Simulator, profile: RobotProfile, io: RobotIO, events: EventLog) -> None:
    """A simulated camera and the line detector for a profile with ``camera:`` (``io.sensors['camera']``)."""
    if profile.section("camera") is None:
        return
    one_opencv_thread()
    config: CameraConfig = section_config(profile, "camera", CameraConfig)
    detector_config: LineDetectorConfig = section_config(profile, "line_detector", LineDetectorConfig)
    _check_h264(profile, config, simulated=True)
    world = sim.world
    raw_floor = world.section("floor")
    raw_effects = world.section("camera") or {}
    try:
        effects = CameraEffects.from_dict(raw_effects)
    except ValueError as exc:
        raise world_problem(world, "camera", exc) from None
    # Seeds drawn now, in attach order, so the run is the same whether or not the camera is ever used.
    floor_seed = int(sim.rng.integers(2**63))
    camera_rng = np.random.default_rng(sim.rng.integers(2**63))
    floor_holder: list[FloorMap] = []

    def floor_map() -> FloorMap:
        if not floor_holder:
            try:
                floor_holder.append(build_floor(raw_floor if raw_floor is not None else PLAIN_FLOOR, floor_seed))
            except ValueError as exc:
                raise world_problem(world, "floor", exc) from None
        return floor_holder[0]

    scenery = Scenery.of_world(world.walls, world.obstacles, raw_floor is not None, floor_seed)
    markers = world_markers(world)

    def make_camera() -> Camera:
        # Built when first used: its floor and ground textures are the simulator's work (cpu_account).
        sim_camera = SIM_CPU.call(CAMERA, lambda: SimCamera(floor_map(), pipeline.geometry, camera_rng, effects,
                                                            scenery, lambda: persons_xy(sim), markers))
        sim_camera.update(sim.truth)  # the live truth: the camera follows the robot and its gimbal
        io.sim_camera = sim_camera
        if config.format == "mjpeg":  # a fake USB camera: the rendered frames come as its own JPEG
            return Camera(SimMjpegCamera(sim_camera).reopen, events.clock, events.sink("camera"), config)
        if config.format == "h264":  # a fake H.264 camera: the rendered frames come as its own access units
            from beastbt.devices.camera import EncodingH264Camera
            return Camera(EncodingH264Camera(sim_camera, config.fps).reopen, events.clock, events.sink("camera"),
                          config)
        return Camera(sim_camera.reopen, events.clock, events.sink("camera"), config)

    pipeline = CameraPipeline(make_camera, config, detector_config, events.sink("camera"))
    try:
        pipeline.check()
    except ValueError as exc:
        raise InvalidInput([profile.doc.problem(("camera",), f"in 'camera': {exc}",
                                                "lower the camera's pitch_deg or raise line_detector.roi_far_m")]) from None
    io.sensors["camera"] = pipeline.poll
    io.capabilities.add("camera")
    io.camera = pipeline
    io.floor_map = floor_map
    # What a live viewer's process needs to build a camera of its own on the same mounting and floor.
    io.viewer_camera = {"floor": raw_floor, "floor_seed": floor_seed, "geometry": pipeline.geometry,
                        "effects": effects, "scenery": scenery, "markers": markers}
    io.closers.append(pipeline.close)


def world_markers(world: Any) -> list:
    """The world's ``tags:`` and ``qr_boards:`` as :class:`~beastbt.sim.markers.PlanarMarker` (none: ``[]``); a tag
    its family does not have is an error at ``tags``, before anything moves."""
    tags, boards = world.data.get("tags"), world.data.get("qr_boards")
    if not tags and not boards:
        return []
    from beastbt.sim.markers import marker_schema_problem, markers_of_world
    why = marker_schema_problem(tags)
    if why is not None and world.doc is not None:
        raise InvalidInput([world.doc.problem(("tags", why[0], "id"), f"tags: {why[1]}",
                                              "use an id the family has, or a family with more ids "
                                              "(apriltag_36h11 has 587)")])
    try:
        return markers_of_world(tags, boards)
    except ValueError as exc:
        raise world_problem(world, "tags", exc) from None


def persons_xy(sim: Simulator) -> Optional[list[tuple[float, float]]]:
    """Where the world's persons stand now ((x, y) m, world order), or None in a world without persons."""
    contact = getattr(sim.drive, "contact", None)
    xy = getattr(contact, "person_xy", None)
    if xy is None or not len(xy):
        return None
    return [(float(x), float(y)) for x, y in xy]


def floor_of(io: RobotIO) -> Optional[FloorMap]:
    """The simulated robot's floor (built on first call), or None without a simulated camera."""
    get: Optional[Callable[[], FloorMap]] = io.floor_map
    return get() if get is not None else None


class CameraPart(Part):
    """``camera:`` (with ``line_detector:``): frames and line observations (``io.sensors['camera']``)."""

    name = "camera"
    section = "camera"
    schema = "parts/camera.schema.json"
    opens = "V4L2 video device"
    fills = ("camera_frame", "line")

    def attach(self, build: Build) -> None:
        """Open the camera (robot) or the simulated one (simulator) when the profile has ``camera:``."""
        assert build.io is not None
        if build.mode == REAL:
            attach_camera(build.profile, build.io, build.clock, build.events)
        elif build.mode == SIM:
            assert build.sim is not None
            attach_sim_camera(build.sim, build.profile, build.io, build.events)


__all__ = ["CameraPart", "attach_camera", "attach_sim_camera", "build_floor", "floor_of", "persons_xy", "PLAIN_FLOOR",
           "one_opencv_thread", "OPENCV_THREADS"]
