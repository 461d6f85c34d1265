"""How to make a serial port appear on a Raspberry Pi, by its name: one hint for the doctor and the drivers.

The Pi 4's primary UART (``/dev/serial0`` -> ``/dev/ttyAMA0`` or
``/dev/ttyS0``) is switched on by raspi-config; the extra PL011 UARTs
(``/dev/ttyAMA1`` to ``/dev/ttyAMA4``) only by a ``dtoverlay=uartN`` line in
``/boot/firmware/config.txt``, which raspi-config does not write; USB adapters
need neither. See docs/hardware/raspberry-pi.md.
"""

from __future__ import annotations

import re

DIALOUT = "add your user to the 'dialout' group (sudo usermod -aG dialout $USER, then log in again)"

_EXTRA_UART = re.compile(r"^/dev/ttyAMA([1-4])$")


def serial_port_hint(port: str) -> str:
    """What to check when serial ``port`` (a device path) cannot be opened or is missing, for that kind of port."""
    extra = _EXTRA_UART.match(port)
    if extra:
        return (f"{port} is one of the Pi 4's extra UARTs: add 'dtoverlay=uart3' (GPIO 4 TX, GPIO 5 RX, where the "
                f"GPS goes; it becomes /dev/ttyAMA1 when it is the only extra UART) or the uartN of your wiring to "
                f"/boot/firmware/config.txt and reboot (only that line enables it: see "
                f"docs/hardware/raspberry-pi.md); and {DIALOUT}")
    if port.startswith(("/dev/ttyUSB", "/dev/ttyACM", "/dev/serial/by-id/")):
        return (f"check the USB cable (ls /dev/ttyUSB* /dev/ttyACM* /dev/serial/by-id/ shows what is plugged in); "
                f"and {DIALOUT}")
    return (f"enable the serial port (raspi-config: interface options, serial port: login shell no, hardware yes; or "
            f"enable_uart=1 in /boot/firmware/config.txt) and {DIALOUT}")
