"""The optional parts of beastbt, imported once so that they register their steps, devices and commands.

Each part lives in its own folder and registers itself with the compiler
(``register_step``), the simulator (``register_sim_device``), the runtime
hooks and the CLI (``COMMANDS``). Importing this module imports them all.
"""

import beastbt.runtime.teleop_runtime  # noqa: F401  (joystick teleop, e-stop, watchdog, the teleop step, --joystick)
import beastbt.runtime.hardware_devices  # noqa: F401  (real CAN/PWM bases, PCA9685 servos, the gamepad)
import beastbt.sim.actuator_attach  # noqa: F401  (CAN/PWM bases and PCA9685 servos on the simulator)
