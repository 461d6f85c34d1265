"""Below the tree: the command mux, the safety gate and watchdog, teleop, and the actuator adapters."""
