"""``beastbt doctor``: probe every device of a robot profile without moving anything.

Each check returns :class:`Finding` lines: ``OK``, ``WARN`` or ``FAIL``, what
was found, and for anything not OK the fix in one sentence. Nothing here
commands motion: the base is only asked for feedback (echo off, feedback
on), the IMU only has ``WHO_AM_I`` read, the camera one frame grabbed.

The checks, in order: the serial ports (present, and no UART used twice),
the base (it answers, and with which firmware), the GPS (NMEA at the set
baud, fix and satellites), the LiDAR (packets, CRC failures, scan rate and
points per scan; an RPLIDAR's health, model and firmware), the IMU
(``WHO_AM_I``), the camera (one frame),
the joystick (present, its name), a CAN interface (up, at the profile's
bitrate), and on a Raspberry Pi the UART set-up (``enable_uart=1``, no login
console on it).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Optional

from beastbt.core.clock import WallClock
from beastbt.core.errors import plain_reason
from beastbt.robot.profile import RobotProfile
from beastbt.robot.serial_hint import serial_port_hint
from beastbt.devices.gamepad_presets import describe_controls

OK, WARN, FAIL = "OK", "WARN", "FAIL"
BASE_WAIT_S = 2.0
"""How long to wait for the base's first T:1001 feedback line, s."""
GPS_WAIT_S = 3.0
"""How long to listen to the GPS (it talks at 1 Hz by default), s."""
LIDAR_WAIT_S = 4.0
"""How long to listen to the LiDAR: an RPLIDAR A1 takes 1-2 s to spin up, then a few revolutions, s."""
LIDAR_SCANS = 5
"""Revolutions to see before the LiDAR's figures are reported."""
LIDAR_CRC_WARN = 0.01
"""A share of bad packets above this is a noisy line (WARN)."""
WHO_AM_I_REGISTER = 0x75
"""MPU9250 register holding the chip id."""
WHO_AM_I = {0x71: "MPU9250", 0x73: "MPU9255"}
"""Chip ids the MPU9250 driver accepts."""


@dataclass(frozen=True)
class Finding:
    """One line of the doctor's report: ``level`` (OK/WARN/FAIL), the device, what was found, the fix."""

    level: str
    device: str
    text: str
    fix: str = ""

    def line(self) -> str:
        """The line as printed: ``FAIL base: nothing on /dev/serial0 in 2 s. Fix: ...``."""
        fix = f". Fix: {self.fix}" if self.fix and self.level != OK else ""
        return f"{self.level:<4} {self.device}: {self.text}{fix}"


@dataclass
class DoctorContext:
    """What the checks may use: the profile, a clock, and the filesystem root (``/`` on the robot)."""

    profile: RobotProfile
    clock: WallClock
    root: Path = Path("/")

    def path(self, absolute: str) -> Path:
        """``absolute`` under :attr:`root`."""
        return self.root / absolute.lstrip("/")


Check = Callable[[DoctorContext], Iterator[Finding]]


# -- serial ports ----------------------------------------------------------------------------------

def serial_ports(profile: RobotProfile) -> list[tuple[str, str]]:
    """(device, port) of every serial device in the profile: the Waveshare base and the GPS."""
    ports = []
    base = profile.section("base") or {}
    if base.get("type", "waveshare_serial") == "waveshare_serial":
        ports.append(("base", str(base.get("port", "/dev/serial0"))))
    gps = profile.section("gps")
    if gps is not None:
        ports.append(("gps", str(gps.get("port", "/dev/serial0"))))
    lidar = profile.section("lidar")
    if lidar is not None:
        ports.append(("lidar", str(lidar.get("port", "/dev/ttyUSB0"))))
    return ports


def check_serial_ports(ctx: DoctorContext) -> Iterator[Finding]:
    """Each serial port exists, and no two devices share one UART (``/dev/serial0`` is a link to one)."""
    seen: dict[str, str] = {}
    for device, port in serial_ports(ctx.profile):
        path = ctx.path(port)
        if not path.exists():
            yield Finding(FAIL, device, f"{port} does not exist", f"check the wiring; {serial_port_hint(port)}")
            continue
        real = os.path.realpath(path)
        if real in seen:
            yield Finding(FAIL, device, f"{port} is the same UART as the {seen[real]}'s ({real})",
                          "give each device its own UART: see docs/hardware/raspberry-pi.md")
            continue
        seen[real] = device
        yield Finding(OK, device, f"{port} exists" + (f" ({real})" if real != str(path) else ""))


# -- the base --------------------------------------------------------------------------------------

def check_base(ctx: DoctorContext) -> Iterator[Finding]:
    """The Waveshare base answers with T:1001 feedback; which firmware; the battery."""
    base = ctx.profile.section("base") or {}
    if base.get("type", "waveshare_serial") != "waveshare_serial":
        return
    from beastbt.devices.waveshare_base import WaveshareBase, WaveshareConfig
    from beastbt.blackboard.types import BatteryState
    config = WaveshareConfig.from_dict({k: v for k, v in base.items()})
    port = _open_serial(config.port, config.baud)
    if isinstance(port, str):
        yield Finding(FAIL, "base", f"cannot open {config.port}: {port}", serial_port_hint(config.port))
        return
    events: list[str] = []
    driver = WaveshareBase(port, config, lambda kind, text: events.append(text))
    try:
        # Only what makes the base talk: echo off, feedback on. No motion command.
        driver._send({"T": 143, "cmd": 0})
        driver._send({"T": 131, "cmd": 1})
        end = ctx.clock.now() + BASE_WAIT_S
        volts: Optional[float] = None
        while ctx.clock.now() < end and (driver.firmware is None or volts is None):
            for reading in driver.poll(ctx.clock.now()):
                if isinstance(reading, BatteryState):
                    volts = reading.voltage_v
            ctx.clock.sleep_until(ctx.clock.now() + 0.02)
    finally:
        try:
            port.close()
        except Exception:  # noqa: BLE001 - closing a vanished port may fail; it is gone anyway
            pass
    if driver.stats.feedback == 0:
        what = f"{driver.stats.lines} lines but no T:1001 feedback" if driver.stats.lines else "nothing"
        yield Finding(FAIL, "base", f"{what} on {config.port} at {config.baud} baud in {BASE_WAIT_S:g} s",
                      "check that the base is switched on, the cable to the ESP32, and the baud (115200)")
        return
    firmware = f"ugv_base_{driver.firmware}" if driver.firmware else "an unknown firmware"
    battery = f", battery {volts:.2f} V" if volts is not None else ""
    yield Finding(OK, "base", f"answers on {config.port}: {firmware}{battery}")
    if driver.firmware == "general":
        yield Finding(WARN, "base", "ugv_base_general reports no wheel odometry (integrated from wheel speeds)",
                      "flash waveshareteam/ugv_base_ros for encoder odometry")
    if config.firmware not in ("auto", driver.firmware):
        yield Finding(FAIL, "base", f"the profile says firmware '{config.firmware}' but the base runs {firmware}",
                      f"set base.firmware to auto or {driver.firmware}")


def _open_serial(path: str, baud: int) -> Any:
    """A pyserial port, or the reason it cannot be opened (a string)."""
    import serial
    try:
        return serial.Serial(path, baud, timeout=0, write_timeout=0.2)
    except (serial.SerialException, OSError, ValueError) as exc:
        return plain_reason(exc)


# -- the GPS -------------------------------------------------------------------------------------

def check_gps(ctx: DoctorContext) -> Iterator[Finding]:
    """NMEA at the profile's baud: whether it talks, its fix and satellites."""
    gps = ctx.profile.section("gps")
    if gps is None:
        return
    import pynmea2
    port_path, baud = str(gps.get("port", "/dev/serial0")), int(gps.get("port_baud", 9600))
    port = _open_serial(port_path, baud)
    if isinstance(port, str):
        yield Finding(FAIL, "gps", f"cannot open {port_path}: {port}", serial_port_hint(port_path))
        return
    buf, good, bad, fix, sats = b"", 0, 0, None, None
    end = ctx.clock.now() + GPS_WAIT_S
    try:
        while ctx.clock.now() < end and (fix is None or good < 3):
            waiting = port.in_waiting
            buf += port.read(waiting) if waiting else b""
            *lines, buf = buf.split(b"\n")
            for raw in lines:
                try:
                    msg = pynmea2.parse(raw.decode("ascii", "strict").strip(), check=True)
                except (pynmea2.ParseError, UnicodeDecodeError, ValueError, AttributeError):
                    bad += 1
                    continue
                good += 1
                if isinstance(msg, pynmea2.types.talker.GGA):
                    fix = int(msg.gps_qual or 0)
                    sats = int(msg.num_sats or 0)
            ctx.clock.sleep_until(ctx.clock.now() + 0.05)
    finally:
        port.close()
    if good == 0:
        if bad or buf:
            yield Finding(FAIL, "gps", f"bytes on {port_path} but no valid NMEA at {baud} baud",
                          "set gps.port_baud to the receiver's speed (the MTK3339 ships at 9600)")
        else:
            yield Finding(FAIL, "gps", f"nothing on {port_path} in {GPS_WAIT_S:g} s",
                          "check the GPS's power and TX wire, and that no console runs on this UART")
        return
    if not fix:
        yield Finding(WARN, "gps", f"talks NMEA at {baud} baud, no fix yet ({sats or 0} satellites)",
                      "give it open sky; a cold start takes a minute or more")
        return
    yield Finding(OK, "gps", f"talks NMEA at {baud} baud: fix quality {fix}, {sats} satellites")


# -- the LiDAR -----------------------------------------------------------------------------------

def check_lidar(ctx: DoctorContext) -> Iterator[Finding]:
    """The LiDAR on its port: packets, CRC failures, scan rate, points per scan; an RPLIDAR's health and info.

    An RPLIDAR A1's motor turns while it is checked (DTR) and is stopped after.
    """
    if ctx.profile.section("lidar") is None:
        return
    from beastbt.devices.ld19 import Ld19Lidar
    from beastbt.devices.lidar_scan import LidarConfig
    from beastbt.devices.rplidar import RplidarA1
    from beastbt.robot.profile import section_config
    config: LidarConfig = section_config(ctx.profile, "lidar", LidarConfig)
    port = _open_serial(config.port, config.port_baud)
    if isinstance(port, str):
        yield Finding(FAIL, "lidar", f"cannot open {config.port}: {port}", serial_port_hint(config.port))
        return
    driver_cls = RplidarA1 if config.type == "rplidar_a1" else Ld19Lidar
    driver = driver_cls(port, ctx.clock, lambda kind, text: None, config=config)
    scans = 0
    try:
        end = ctx.clock.now() + LIDAR_WAIT_S
        while ctx.clock.now() < end and scans < LIDAR_SCANS:
            scans += len(driver.poll())
            if isinstance(driver, RplidarA1) and driver.state == "failed":
                break
            ctx.clock.sleep_until(ctx.clock.now() + 0.01)
    finally:
        driver.close()
    yield from _lidar_findings(driver, config, scans)


def _lidar_findings(driver: Any, config: Any, scans: int) -> Iterator[Finding]:
    from beastbt.devices.rplidar import RplidarA1
    stats, name, baud = driver.stats, config.model["name"], config.port_baud
    where = f"{config.port} at {baud} baud"
    if isinstance(driver, RplidarA1):
        if driver.health is None:
            what = "bytes but no answer it understands" if stats.bytes_read else "no answer"
            yield Finding(FAIL, "lidar", f"{what} to GET_HEALTH on {where} in {LIDAR_WAIT_S:g} s",
                          "check that lidar.type is the LiDAR fitted, the USB adapter's cable and its power, and "
                          "the baud (the A1 talks at 115200)")
            return
        info = driver.info
        about = (f"{info.model_name}, firmware {info.firmware}, hardware {info.hardware}, serial {info.serial_hex}"
                 if info is not None else "no GET_INFO answer")
        if driver.health.status == 2:
            after = " even after a reset" if driver.state == "failed" else ""
            yield Finding(FAIL, "lidar", f"{name} ({about}) reports health {driver.health.text}{after}",
                          "power-cycle it; if the error stays, the unit needs Slamtec's support")
            return
        level = WARN if driver.health.status == 1 else OK
        yield Finding(level, "lidar", f"{name} on {config.port}: {about}; health {driver.health.text}",
                      "watch it: the A1 reports a warning before it stops in protection")
    if stats.packets == 0:
        if stats.bytes_read == 0:
            yield Finding(FAIL, "lidar", f"nothing on {where} in {LIDAR_WAIT_S:g} s",
                          "check the LiDAR's power and cable (an LD19 streams as soon as it has power; "
                          "an RPLIDAR needs its motor supply)")
        else:
            yield Finding(FAIL, "lidar", f"{stats.bytes_read} bytes on {where} but no {name} packets",
                          f"check lidar.type (this is not a {name}?) and lidar.baud")
        return
    bad = stats.crc_failures / max(1, stats.packets + stats.crc_failures)
    figures = (f"{stats.packets} {'packets' if config.type == 'ld19' else 'samples'}, {stats.crc_failures} "
               f"{'CRC' if config.type == 'ld19' else 'check-bit'} failures")
    if scans == 0:
        yield Finding(FAIL, "lidar", f"{figures} on {config.port} but no whole revolution in {LIDAR_WAIT_S:g} s "
                                     f"({stats.spinup_packets} dropped while the motor was not at speed)",
                      "the motor does not reach speed: check its supply (5 V, enough current from the USB port or "
                      "adapter)" + (" and that DTR reaches the adapter" if config.type == "rplidar_a1" else ""))
        return
    scan = driver.latest_scan
    returns = scan.valid_count if scan is not None else 0
    text = (f"{figures}; {stats.scan_rate_hz:.1f} Hz, {stats.points_per_scan} points per scan "
            f"({returns} with a return in range)")
    if bad > LIDAR_CRC_WARN:
        yield Finding(WARN, "lidar", f"{text}: {bad:.1%} bad", "a noisy line: use a shorter or shielded cable, "
                                                               "check the ground and the baud")
    elif returns == 0:
        yield Finding(WARN, "lidar", f"{text}: no point in range", "take the cover off the window, or check "
                                                                  "lidar.range_m and lidar.ignore_deg")
    else:
        yield Finding(OK, "lidar", f"{name}: {text}")


# -- the IMU -------------------------------------------------------------------------------------

def check_imu(ctx: DoctorContext) -> Iterator[Finding]:
    """The MPU9250 answers WHO_AM_I on its I2C bus."""
    imu = ctx.profile.section("imu")
    if imu is None:
        return
    bus_number, address = int(imu.get("bus", 1)), int(imu.get("address", 0x68))
    try:
        import smbus2
        bus = smbus2.SMBus(bus_number)
    except (OSError, ValueError, ImportError) as exc:
        yield Finding(FAIL, "imu", f"cannot open /dev/i2c-{bus_number} ({plain_reason(exc)})",
                      "enable I2C (raspi-config: interface options, I2C) and add your user to the 'i2c' group")
        return
    try:
        who = bus.read_byte_data(address, WHO_AM_I_REGISTER)
    except OSError as exc:
        yield Finding(FAIL, "imu", f"no answer at 0x{address:02x} on /dev/i2c-{bus_number} ({plain_reason(exc)})",
                      "check the IMU's wiring and address (i2cdetect -y 1)")
        return
    finally:
        bus.close()
    if who in WHO_AM_I:
        yield Finding(OK, "imu", f"{WHO_AM_I[who]} answers WHO_AM_I 0x{who:02x} at 0x{address:02x}")
    else:
        yield Finding(FAIL, "imu", f"WHO_AM_I is 0x{who:02x} at 0x{address:02x}, not an MPU9250 (0x71/0x73)",
                      "check imu.address: another chip answers there")


# -- the camera ----------------------------------------------------------------------------------

def check_camera(ctx: DoctorContext) -> Iterator[Finding]:
    """One frame from the camera: through picamera2 when installed, else V4L2 through OpenCV."""
    camera = ctx.profile.section("camera")
    if camera is None:
        return
    from beastbt.devices.camera import CameraConfig, camera_backend, open_video_capture
    from beastbt.robot.profile import section_config
    config: CameraConfig = section_config(ctx.profile, "camera", CameraConfig)
    backend = camera_backend(config)
    device = str(config.device)
    if backend == "v4l2" and device.startswith("/") and not ctx.path(device).exists():
        yield Finding(FAIL, "camera", f"{device} does not exist",
                      "check the camera's cable (a USB camera appears as /dev/videoN; a Pi camera needs picamera2: "
                      "sudo apt install python3-picamera2, and a venv made with --system-site-packages)")
        return
    try:
        capture = open_video_capture(config)
        ok, frame = capture.read()
        capture.release()
    except Exception as exc:  # noqa: BLE001 - any backend failure is the finding
        ok, frame = False, None
        reason = str(exc)
    else:
        reason = "no frame"
    if not ok or frame is None:
        yield Finding(FAIL, "camera", f"{config.device} gives no frame through {backend} ({reason})",
                      "check the camera cable and that it is enabled (rpicam-hello lists it)")
        return
    height, width = frame.shape[:2]
    yield Finding(OK, "camera", f"{config.device} gives {width}x{height} frames through {backend}")


# -- the joystick --------------------------------------------------------------------------------

def check_joystick(ctx: DoctorContext) -> Iterator[Finding]:
    """The gamepad's device is there, with its name."""
    joystick = ctx.profile.section("joystick")
    if joystick is None:
        return
    path = str(joystick.get("device", "/dev/input/js0"))
    if not ctx.path(path).exists():
        yield Finding(WARN, "joystick", f"{path} is not there (teleop and the joystick e-stop need it)",
                      "plug in or pair the gamepad (ls /dev/input/js*), and add your user to the 'input' group")
        return
    from beastbt.devices.joystick import device_name
    from beastbt.robot.actuator_profile import joystick_mapping
    name = device_name(str(ctx.path(path)))
    mapping, preset = joystick_mapping(ctx.profile).for_device(name)
    if name is None:
        yield Finding(WARN, "joystick", f"{path} is there but does not tell its name (JSIOCGNAME): preset {preset.name}",
                      "check its buttons with beastbt joystick test; set joystick.preset or the numbers explicitly")
        return
    yield Finding(OK, "joystick", f"{path}: '{name}', preset {preset.name} ({describe_controls(mapping, preset)})")


# -- CAN -------------------------------------------------------------------------------------------

def check_can(ctx: DoctorContext) -> Iterator[Finding]:
    """A SocketCAN interface is up at the profile's bitrate (the kernel sets it, not python-can)."""
    base = ctx.profile.section("base") or {}
    if base.get("type") != "can":
        return
    from beastbt.actuation.can_base import bring_up_hint, socketcan_link
    from beastbt.robot.actuator_profile import can_config
    config = can_config(ctx.profile)
    if config.interface != "socketcan":
        yield Finding(OK, "can", f"interface '{config.interface}' is not checked by the doctor (only socketcan is)")
        return
    link = socketcan_link(config.channel)
    if link is None:
        yield Finding(FAIL, "can", f"there is no interface {config.channel}",
                      f"enable the CAN HAT's overlay (e.g. dtoverlay=mcp2515-can0 in config.txt), reboot, then "
                      f"{bring_up_hint(config)}")
    elif not link["up"]:
        yield Finding(FAIL, "can", f"{config.channel} is down", bring_up_hint(config))
    elif link["bitrate"] is not None and link["bitrate"] != config.bitrate:
        yield Finding(FAIL, "can", f"{config.channel} runs at {link['bitrate']} bit/s, the profile says {config.bitrate}",
                      bring_up_hint(config))
    else:
        rate = f" at {link['bitrate']} bit/s" if link["bitrate"] is not None else ""
        yield Finding(OK, "can", f"{config.channel} is up{rate}")


# -- the Raspberry Pi's UART -----------------------------------------------------------------------

def check_pi_uart(ctx: DoctorContext) -> Iterator[Finding]:
    """On a Raspberry Pi with a serial device: ``enable_uart=1`` in config.txt, no login console on the UART."""
    model_file = ctx.path("/proc/device-tree/model")
    try:
        model = model_file.read_bytes().decode("ascii", "replace").strip("\0\n ")
    except OSError:
        return  # not a Pi: nothing to check
    if "Raspberry Pi" not in model or not serial_ports(ctx.profile):
        return
    boot = next((d for d in ("/boot/firmware", "/boot") if ctx.path(d + "/config.txt").exists()), None)
    if boot is None:
        yield Finding(WARN, "pi", f"{model}: no config.txt in /boot/firmware or /boot", "check the boot partition")
        return
    config = _active_lines(ctx.path(boot + "/config.txt"))
    if "enable_uart=1" in config:
        yield Finding(OK, "pi", f"{model}: enable_uart=1 in {boot}/config.txt")
    else:
        yield Finding(FAIL, "pi", f"{model}: the UART is not enabled in {boot}/config.txt",
                      "add enable_uart=1 (raspi-config: serial port hardware yes) and reboot")
    cmdline_path = ctx.path(boot + "/cmdline.txt")
    cmdline = cmdline_path.read_text(encoding="utf-8", errors="replace") if cmdline_path.exists() else ""
    consoles = [w for w in cmdline.split() if w.startswith("console=") and ("serial" in w or "ttyS" in w or "ttyAMA" in w)]
    if consoles:
        yield Finding(FAIL, "pi", f"a login console runs on the UART ({' '.join(consoles)} in {boot}/cmdline.txt)",
                      "remove it (raspi-config: serial port, login shell no) and reboot")
    else:
        yield Finding(OK, "pi", "no login console on the UART")


def _active_lines(path: Path) -> set[str]:
    lines = set()
    for raw in path.read_text(encoding="utf-8", errors="replace").splitlines():
        line = raw.split("#", 1)[0].strip().replace(" ", "")
        if line:
            lines.add(line)
    return lines


CHECKS: tuple[Check, ...] = (check_pi_uart, check_serial_ports, check_base, check_gps, check_lidar, check_imu,
                             check_camera, check_joystick, check_can)
"""Every check, in the order the report prints them."""


def diagnose(profile: RobotProfile, clock: Optional[WallClock] = None, root: Path = Path("/")) -> list[Finding]:
    """Run every check on ``profile``'s devices; the findings in order. Nothing moves."""
    ctx = DoctorContext(profile, clock if clock is not None else WallClock(), root)
    findings: list[Finding] = []
    ports_failed: set[str] = set()
    for check in CHECKS:
        for finding in check(ctx):
            if check is check_serial_ports and finding.level == FAIL:
                ports_failed.add(finding.device)
            if check in (check_base, check_gps, check_lidar) and finding.device in ports_failed:
                continue  # the port itself already failed: say it once
            findings.append(finding)
    return findings


__all__ = ["Finding", "diagnose", "CHECKS", "OK", "WARN", "FAIL", "serial_ports"]
