"""An emulated I2C bus: the simulator's stand-in for ``smbus2.SMBus``.

Devices (an MPU9250, an AK8963, a PCA9685...) attach at their 7-bit address
as :class:`RegisterDevice` objects holding a 256-byte register map. Drivers
talk to this bus exactly as to ``smbus2.SMBus``; a missing address raises
``OSError(errno.EREMOTEIO)`` as the kernel does, and faults can be injected.
"""

from __future__ import annotations

import errno
from typing import Any, Callable, Optional, Sequence

from beastbt.core.bounded import trim_front
from beastbt.sim.cpu_account import SIM_CPU, kind_of

WRITES_KEPT = 4096
"""A device's ``writes`` keeps at least its last this many writes (at most twice as many): a PWM base is
written at every tick, for as long as the run lasts."""


class RegisterDevice:
    """A device on the emulated bus: a register map with auto-incrementing block access.

    Subclasses override :meth:`on_write` to react to writes (mode changes,
    commands) and :meth:`on_read` to produce live data (sensor samples).
    """

    def __init__(self) -> None:
        self.registers = bytearray(256)
        self.writes: list[tuple[int, int]] = []
        """The (register, value) pairs written, in order (lets tests pin the exact bytes): all of them until
        2 * :data:`WRITES_KEPT`, then the latest."""

    def on_write(self, register: int, value: int) -> None:
        """Called after each byte is stored; default does nothing."""

    def on_read(self, register: int) -> int:
        """Return the byte at ``register``; default reads the map."""
        return self.registers[register & 0xFF]

    def next_register(self, register: int) -> int:
        """Which register a block access moves to after ``register`` (default: the next one)."""
        return (register + 1) & 0xFF

    def write(self, register: int, value: int) -> None:
        """Store one byte and notify the device."""
        register &= 0xFF
        value &= 0xFF
        self.writes.append((register, value))
        trim_front(self.writes, WRITES_KEPT)
        self.registers[register] = value
        self.on_write(register, value)


class SimI2CBus:
    """An SMBus-like bus with emulated devices at their addresses.

    ``fail_next`` makes the next N transactions raise ``OSError(EIO)``;
    ``detach`` removes a device (as if unplugged).
    """

    def __init__(self) -> None:
        self.devices: dict[int, RegisterDevice] = {}
        self.fail_next = 0
        self.transactions = 0

    def attach(self, i2c_addr: int, device: RegisterDevice) -> None:
        """Put ``device`` on the bus at ``i2c_addr``."""
        self.devices[i2c_addr] = device

    def detach(self, i2c_addr: int) -> None:
        """Remove the device at ``i2c_addr`` (reads then fail as on a real bus)."""
        self.devices.pop(i2c_addr, None)

    def _device(self, i2c_addr: int) -> RegisterDevice:
        self.transactions += 1
        if self.fail_next > 0:
            self.fail_next -= 1
            raise OSError(errno.EIO, f"I2C transfer to 0x{i2c_addr:02x} failed (injected fault)")
        dev = self.devices.get(i2c_addr)
        if dev is None:
            raise OSError(errno.EREMOTEIO, f"no device answers at I2C address 0x{i2c_addr:02x}")
        return dev

    @staticmethod
    def _answer(dev: Any, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)``: the device answering, which is the simulator's work (:mod:`beastbt.sim.cpu_account`; its
        kind is looked up only while the accounting is on)."""
        if not SIM_CPU.enabled:
            return fn(*args)
        return SIM_CPU.call(kind_of(dev), fn, *args)

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        """Read one byte from ``register`` of the device at ``i2c_addr``."""
        dev = self._device(i2c_addr)
        return self._answer(dev, dev.on_read, register & 0xFF)

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        """Write one byte to ``register`` of the device at ``i2c_addr``."""
        dev = self._device(i2c_addr)
        self._answer(dev, dev.write, register, value)

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        """Read ``length`` bytes from ``register`` on in one transaction."""
        dev = self._device(i2c_addr)
        return self._answer(dev, _read_block, dev, register & 0xFF, length)

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int]) -> None:
        """Write bytes from ``register`` on in one transaction."""
        dev = self._device(i2c_addr)
        self._answer(dev, _write_block, dev, register & 0xFF, data)

    def close(self) -> None:
        """Nothing to release; present for smbus2 compatibility."""

    def device(self, i2c_addr: int) -> Optional[RegisterDevice]:
        """The emulated device at ``i2c_addr`` (for tests), or None."""
        return self.devices.get(i2c_addr)


def _read_block(dev: Any, reg: int, length: int) -> list[int]:
    """``length`` bytes from ``reg`` on, the device's register pointer advancing as a block read does."""
    out = []
    for _ in range(length):
        out.append(dev.on_read(reg))
        reg = dev.next_register(reg)
    return out


def _write_block(dev: Any, reg: int, data: Sequence[int]) -> None:
    """Write ``data`` from ``reg`` on, the device's register pointer advancing as a block write does."""
    for value in data:
        dev.write(reg, value)
        reg = dev.next_register(reg)
