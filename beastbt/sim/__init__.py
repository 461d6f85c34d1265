"""The simulator: world, robot dynamics, and device emulators behind the same interfaces the drivers use."""
