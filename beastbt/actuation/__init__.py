"""Below the tree: the command mux (e-stop latch, sources by priority), the safety gate (limits), the command watchdog, teleop_twist_joy logic, and the base and servo adapters."""
