"""A robot from its profile: the profile itself, its ports and devices (``RobotIO``), the part protocol and the assembly that wires every part and the safety layers."""
