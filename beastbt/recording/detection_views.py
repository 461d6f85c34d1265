"""What the detectors found, as Foxglove draws it: ``/camera/detections`` over the image and ``/camera/tags`` in 3D.

Two halves, one per process, as for the rest of the recording:

* the tick side: a :class:`~beastbt.vision.detection_feed.DetectionFeed` attached to the run's
  :class:`~beastbt.vision.watch.VisionWatch`; each tick the recorder sends its new frame entries as one
  ``("detections", now_s, entries)`` item (none while no detector is awake);
* the writer side (:func:`image_annotations`, :func:`tags_update`): each entry becomes a
  ``foxglove.ImageAnnotations`` on ``/camera/detections`` (tag outlines with their id and distance,
  QR outlines with their text, the colour blob's box, the moving region's box, in the pixels of
  the published ``/camera/image``) and, when it holds tags, a ``foxglove.SceneUpdate`` on
  ``/camera/tags``: each tag a thin square plate where it was seen, in ``base_link`` at the frame's
  time (not frame-locked: it stays where it was in the world), living :data:`TAG_LIFETIME_S`.

Both are stamped with the time of the ``/camera/image`` message of the frame they came from (the
writer knows it by the frame's sequence number), so Foxglove's image panel pairs them with it.
An entry with no kind (the detectors went to sleep) clears the image's annotations.
"""

from __future__ import annotations

from typing import Any, Optional

from beastbt.recording.foxglove import color, fox_time, quaternion, vector3

TAG_LIFETIME_S = 0.5
"""A tag drawn in 3D disappears after this long unless seen again, s."""
TAG_THICKNESS_M = 0.01
"""How thick a tag's plate is drawn, m."""

TAG_RGBA = color(0.1, 0.9, 0.2)
QR_RGBA = color(0.0, 0.8, 1.0)
MOTION_RGBA = color(1.0, 0.55, 0.0)
MOTION_WARMING_RGBA = color(1.0, 0.85, 0.3, 0.6)
COLOUR_RGBA = {"red": color(1.0, 0.15, 0.15), "green": color(0.2, 1.0, 0.2), "blue": color(0.3, 0.5, 1.0),
               "yellow": color(1.0, 0.95, 0.1)}
OTHER_COLOUR_RGBA = color(1.0, 0.2, 1.0)
_CLEAR = color(0.0, 0.0, 0.0, 0.0)
_TEXT_BG = color(0.0, 0.0, 0.0, 0.6)
_WHITE = color(1.0, 1.0, 1.0)
_TAG_PLATE = color(0.95, 0.95, 0.95, 0.9)


def _outline(t: dict, points: list[list[float]], rgba: dict, scale: float, thickness: float = 2.0) -> dict:
    """A closed outline (``LINE_LOOP``) through ``points`` (frame pixels, scaled by ``scale``)."""
    return {"timestamp": t, "type": 2, "points": [{"x": u * scale, "y": v * scale} for u, v in points],
            "outline_color": rgba, "outline_colors": [], "fill_color": _CLEAR, "thickness": thickness}


def _box(t: dict, box: list[int], rgba: dict, scale: float) -> dict:
    """A box ``[x, y, w, h]`` (frame pixels) as an outline."""
    x, y, w, h = box
    return _outline(t, [[x, y], [x + w, y], [x + w, y + h], [x, y + h]], rgba, scale)


def _label(t: dict, u: float, v: float, text: str, rgba: dict) -> dict:
    """A caption whose baseline is just above (u, v) (published pixels), kept inside the picture's top."""
    return {"timestamp": t, "position": {"x": u, "y": max(12.0, v - 4.0)}, "text": text, "font_size": 12.0,
            "text_color": rgba, "background_color": _TEXT_BG}


def image_annotations(t_ns: int, entry: dict, scale: float = 1.0) -> dict:
    """One frame entry (:mod:`beastbt.vision.detection_feed`) as ``foxglove.ImageAnnotations`` stamped ``t_ns``;
    ``scale``: published image pixels per frame pixel (the recording may shrink the image)."""
    t = fox_time(t_ns)
    points: list[dict] = []
    texts: list[dict] = []
    for tag in entry.get("tags", ()):
        points.append(_outline(t, tag["corners"], TAG_RGBA, scale, 3.0))
        u = min(c[0] for c in tag["corners"]) * scale
        v = min(c[1] for c in tag["corners"]) * scale
        texts.append(_label(t, u, v, f"tag {tag['id']} {tag['distance_m']:.2f} m", TAG_RGBA))
    for qr in entry.get("qr", ()):
        points.append(_outline(t, qr["corners"], QR_RGBA, scale))
        u = min(c[0] for c in qr["corners"]) * scale
        v = min(c[1] for c in qr["corners"]) * scale
        texts.append(_label(t, u, v, f"qr {qr['text']}", QR_RGBA))
    for blob in entry.get("colour", ()):
        rgba = COLOUR_RGBA.get(blob["name"], OTHER_COLOUR_RGBA)
        points.append(_box(t, blob["box"], rgba, scale))
        texts.append(_label(t, blob["box"][0] * scale, blob["box"][1] * scale,
                            f"{blob['name']} {blob['area_frac'] * 100:.1f} %", rgba))
    motion = entry.get("motion")
    if motion is not None and motion["box"] is not None and motion["warm"]:  # warming up, every pixel is "new"
        rgba = MOTION_RGBA if motion["moving"] else MOTION_WARMING_RGBA
        points.append(_box(t, motion["box"], rgba, scale))
        texts.append(_label(t, motion["box"][0] * scale, (motion["box"][1] + motion["box"][3]) * scale + 16.0,
                            f"motion {motion['area_frac'] * 100:.1f} %", rgba))
    return {"circles": [], "points": points, "texts": texts}


def tags_update(t_ns: int, frame_id: str, entry: dict) -> Optional[dict]:
    """The entry's tags as a ``foxglove.SceneUpdate`` in ``frame_id`` (base_link): a plate and its id for each tag
    placed in the base frame; None when the entry has no tag with a pose."""
    entities = []
    t = fox_time(t_ns)
    life = {"sec": int(TAG_LIFETIME_S), "nsec": int(round((TAG_LIFETIME_S % 1.0) * 1e9))}
    for tag in entry.get("tags", ()):
        if tag["position_m"] is None or tag["facing_rad"] is None:
            continue
        x, y, z = tag["position_m"]
        pose = {"position": vector3(x, y, z), "orientation": quaternion(yaw_rad=tag["facing_rad"])}
        side = tag["size_m"]
        above = {"position": vector3(x, y, z + 0.6 * side + 0.05), "orientation": quaternion()}
        entities.append({"timestamp": t, "frame_id": frame_id, "id": f"tag/{tag['family']}/{tag['id']}",
                         "lifetime": life, "frame_locked": False,
                         "metadata": [{"key": "distance_m", "value": f"{tag['distance_m']:.3f}"}],
                         "arrows": [{"pose": pose, "shaft_length": 0.15, "shaft_diameter": 0.01, "head_length": 0.05,
                                     "head_diameter": 0.03, "color": TAG_RGBA}],
                         "cubes": [{"pose": pose, "size": vector3(TAG_THICKNESS_M, side, side), "color": _TAG_PLATE}],
                         "spheres": [], "cylinders": [], "lines": [], "triangles": [],
                         "texts": [{"pose": above, "billboard": True, "font_size": 14.0, "scale_invariant": True,
                                    "color": TAG_RGBA, "text": f"tag {tag['id']}"}],
                         "models": []})
    if not entities:
        return None
    return {"deletions": [], "entities": entities}


def published_scale(width_px: int, max_width_px: int) -> float:
    """Published pixels per frame pixel: the recording shrinks images wider than ``max_width_px`` (0: never)."""
    if max_width_px and width_px > max_width_px:
        return max_width_px / float(width_px)
    return 1.0


__all__ = ["image_annotations", "tags_update", "published_scale", "TAG_LIFETIME_S"]
