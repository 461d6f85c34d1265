"""Local navigation around obstacles: the rolling local costmap from LiDAR scans and the local (DWA) planner.

Both work in the ``odom`` frame (the dead-reckoned pose, which never jumps,
unlike the GPS-fused one) and know nothing of the tree: ``go_to``, ``route``
and ``return_home`` (:mod:`beastbt.behaviours.navigation`) feed them scans and
poses and take the command they choose.
"""
