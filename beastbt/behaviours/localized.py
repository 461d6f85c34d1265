"""The condition ``localized``: the robot knows where it is on the mission's map.

It reads ``map_pose`` (written by the map localisation of a mission with
``map:``): it holds while ``map_pose.localized`` is true, that is while the
LiDAR's scans match the map (the localiser's ``lost_quality`` and
``lost_after_s``); it does not hold once they have stopped matching. Without
a map pose (a mission without ``map:``, or before the first tick) it is
unknown, which never holds (``not localized`` stays unknown too).

```yaml
- abort_if: {not: localized}
  steps:
    - drive: {distance: 5 m}
```
"""

from __future__ import annotations

from typing import Optional

from beastbt.behaviours.conditions import ConditionReader

LOCALIZED_READS = ("map_pose",)
"""What the condition reads: the part that fills it stays awake."""


def localized(r: ConditionReader) -> Optional[bool]:
    """True while the pose on the map is trusted, False once the scans have stopped matching, None without one."""
    pose = r.get("map_pose")
    if pose is None:
        return None
    return bool(getattr(pose, "localized", False))


__all__ = ["localized", "LOCALIZED_READS"]
