"""The interfaces every driver talks through, on the robot and in the simulator.

A driver never knows whether it speaks to hardware or to an emulator: on the
robot these are a ``serial.Serial``, an ``smbus2.SMBus``, a ``can.BusABC`` and a
``cv2.VideoCapture``; in the simulator they are emulators in ``beastbt.sim``
that implement the same methods. Only the subset listed here may be used by
drivers, so that both sides stay interchangeable.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Optional, Protocol, Sequence

if TYPE_CHECKING:  # only in annotations: the interfaces cost no NumPy import
    import numpy as np


class SerialLike(Protocol):
    """The part of ``serial.Serial`` (pyserial) that drivers use.

    ``read`` must not block longer than the port's timeout; drivers open real
    ports with ``timeout=0`` (non-blocking) and read ``in_waiting`` bytes.
    """

    is_open: bool

    @property
    def in_waiting(self) -> int:
        """Number of bytes that can be read without blocking."""
        ...

    def read(self, size: int = 1) -> bytes:
        """Read up to ``size`` bytes."""
        ...

    def write(self, data: bytes) -> Optional[int]:
        """Write bytes; return the count written."""
        ...

    def close(self) -> None:
        """Close the port."""
        ...


class SMBusLike(Protocol):
    """The part of ``smbus2.SMBus`` that drivers use (all addresses 7-bit).

    Errors are raised as ``OSError`` (as the kernel's I2C driver does).
    """

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        """Read one byte from ``register``."""
        ...

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        """Write one byte to ``register``."""
        ...

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        """Read ``length`` bytes starting at ``register`` in one transaction."""
        ...

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int]) -> None:
        """Write bytes starting at ``register`` in one transaction."""
        ...


class FrameSource(Protocol):
    """The part of ``cv2.VideoCapture`` that the camera driver uses."""

    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        """True while the source can deliver frames."""
        ...

    def read(self) -> tuple[bool, Optional[np.ndarray]]:
        """Return ``(ok, frame)``; frame is BGR uint8, shape (h, w, 3)."""
        ...

    def release(self) -> None:
        """Close the source."""
        ...


EventSink = Callable[[str, str], None]
"""Where drivers report what went wrong: ``sink(kind, text)``.

``kind`` is a short machine word (``gps_checksum``, ``imu_i2c_error``,
``device_lost``...), ``text`` a sentence for a person. The runtime stamps it
with the clock and puts it in the run's events.
"""


def ignore_events(kind: str, text: str) -> None:
    """An :data:`EventSink` that drops everything (for tools and tests)."""
