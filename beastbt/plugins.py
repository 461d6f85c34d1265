"""The optional parts of beastbt, imported once so that they register their steps, devices and commands.

Each part lives in its own folder and registers itself with the compiler
(``register_step``), the simulator (``register_sim_device``), the runtime
hooks and the CLI (``COMMANDS``). Importing this module imports them all.
"""

import beastbt.recording.recorder  # noqa: F401  (every run recorded as MCAP)
import beastbt.parts.teleop  # noqa: F401  (joystick teleop, e-stop, watchdog, the teleop step, --joystick)
import beastbt.parts.hardware_devices  # noqa: F401  (real CAN/PWM bases, PCA9685 servos, the gamepad)
import beastbt.parts.sim_actuators  # noqa: F401  (CAN/PWM bases and PCA9685 servos on the simulator)
import beastbt.recording.replay  # noqa: F401  (beastbt replay)
import beastbt.recording.report  # noqa: F401  (beastbt report)
import beastbt.recording.runs_list  # noqa: F401  (beastbt runs)
import beastbt.parts.sim_gps_imu  # noqa: F401  (emulated GPS and IMU read by the real drivers on the simulator)
import beastbt.parts.navigation  # noqa: F401  (the EKF as estimator, navigation tuning, return_home handlers)
import beastbt.parts.navigation_steps  # noqa: F401  (the go_to, route and return_home steps)
import beastbt.parts.nav_summary  # noqa: F401  (waypoints and truth position errors in the summary)
import beastbt.commands.gps  # noqa: F401  (beastbt gps decode FILE)
import beastbt.parts.nav_hardware  # noqa: F401  (the real GPS and IMU from a robot profile)
import beastbt.parts.sim_camera  # noqa: F401  (the simulated camera: the world's floor through the real camera driver)
import beastbt.parts.line_following  # noqa: F401  (follow_line, the real camera, line truth metrics)
import beastbt.live.video_stream  # noqa: F401  (beastbt run --stream: live MJPEG video over HTTP)
