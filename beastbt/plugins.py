"""The optional parts of beastbt, imported once so that they register their steps, devices and commands.

Each part lives in its own folder and registers itself with the compiler
(``register_step``), the simulator (``register_sim_device``), the runtime
hooks and the CLI (``COMMANDS``). Importing this module imports them all.
"""

import beastbt.runtime.recording  # noqa: F401  (every run recorded as MCAP)
import beastbt.runtime.teleop_runtime  # noqa: F401  (joystick teleop, e-stop, watchdog, the teleop step, --joystick)
import beastbt.runtime.hardware_devices  # noqa: F401  (real CAN/PWM bases, PCA9685 servos, the gamepad)
import beastbt.sim.actuator_attach  # noqa: F401  (CAN/PWM bases and PCA9685 servos on the simulator)
import beastbt.runtime.replay  # noqa: F401  (beastbt replay)
import beastbt.runtime.report  # noqa: F401  (beastbt report)
import beastbt.runtime.runs_list  # noqa: F401  (beastbt runs)
import beastbt.sim.gps_imu_attach  # noqa: F401  (emulated GPS and IMU read by the real drivers on the simulator)
import beastbt.runtime.navigation_runtime  # noqa: F401  (the EKF as estimator, navigation tuning, return_home handlers)
import beastbt.behaviours.navigation_steps  # noqa: F401  (the go_to, route and return_home steps)
import beastbt.runtime.nav_summary  # noqa: F401  (waypoints and truth position errors in the summary)
import beastbt.devices.gps_cli  # noqa: F401  (beastbt gps decode FILE)
import beastbt.runtime.nav_hardware  # noqa: F401  (the real GPS and IMU from a robot profile)
import beastbt.sim.camera_attach  # noqa: F401  (the simulated camera: the world's floor through the real camera driver)
import beastbt.runtime.vision_runtime  # noqa: F401  (follow_line, the real camera, line truth metrics)
import beastbt.runtime.video_stream  # noqa: F401  (beastbt run --stream: live MJPEG video over HTTP)
