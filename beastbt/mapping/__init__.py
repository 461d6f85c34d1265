"""Maps: the occupancy grid in ROS map_server format, building one from scans (SLAM), and drawing shapes into one.

A map is shared by estimation (localisation on it) and navigation (global
planning on it), so it lives beside them, on their layer.
"""
