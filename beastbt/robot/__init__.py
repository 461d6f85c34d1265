"""A robot from its profile: the profile itself, its ports and devices (``RobotIO``), the part protocol, and helpers to open a real robot's ports. The assembly itself is ``beastbt.assembly``."""
