"""Linux joystick API reader (``/dev/input/js0``): 8-byte events into a named JoystickState.

The kernel delivers one event per axis move or button change:
``struct js_event { u32 time_ms; s16 value; u8 type; u8 number; }``
(little-endian; ``type`` 0x01 button, 0x02 axis, ORed with 0x80 for the
burst of initial states sent right after the device is opened). Reads are
non-blocking and may stop in the middle of an event, so partial events are
kept for the next poll. When the pad is unplugged the state goes stale and
every button reads released (a held deadman counts as released); the driver
keeps trying to reopen it. The kernel only hands out whole events, so the
stream stays aligned; an 8-byte event that cannot be real (unknown type, a
button value other than 0/1) is dropped whole and counted as garbage.

:class:`JoystickMapping` says which axis and button numbers mean what
(robot profile ``joystick:``); the defaults fit an Xbox- or PlayStation-style
pad with the Linux ``xpad``/``hid-sony`` drivers.
"""

from __future__ import annotations

import errno
import os
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable, Optional

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import JoystickState
from beastbt.core.config import dataclass_from_dict
from beastbt.devices.interfaces import EventSink, ignore_events
from beastbt.core.clock import Clock

JS_EVENT = struct.Struct("<IhBB")
"""One Linux joystick event: time (ms), value, type, number."""
JS_EVENT_SIZE = JS_EVENT.size  # 8 bytes
JS_EVENT_BUTTON = 0x01
JS_EVENT_AXIS = 0x02
JS_EVENT_INIT = 0x80
AXIS_FULL_SCALE = 32767  # the kernel reports axes as -32767..32767

# Names of the axes and buttons in JoystickState (what teleop and the mux read).
AXIS_LINEAR = "linear"
AXIS_ANGULAR = "angular"
BUTTON_ENABLE = "enable"
BUTTON_TURBO = "turbo"
BUTTON_ESTOP = "estop"
BUTTON_ESTOP_RESET = "estop_reset"
AXIS_NAMES = (AXIS_LINEAR, AXIS_ANGULAR)
BUTTON_NAMES = (BUTTON_ENABLE, BUTTON_TURBO, BUTTON_ESTOP, BUTTON_ESTOP_RESET)

if TYPE_CHECKING:
    from beastbt.devices.gamepad_presets import GamepadPreset

PRESET_KEYS = ("linear_axis", "invert_linear", "angular_axis", "invert_angular", "enable_button", "turbo_button",
               "estop_button", "estop_reset_buttons")
"""JoystickMapping fields a gamepad preset sets (unless the profile wrote them)."""

ByteSource = Callable[[], bytes]
"""An open joystick: returns the bytes available now (b"" if none); raises OSError when gone."""


@dataclass
@schema_defaults("parts/joystick.schema.json", computed={"explicit": "what the profile wrote, not a knob"},
                 convert={"estop_reset_buttons": lambda v: tuple(v) if v is not None else None})
class JoystickMapping:
    """Which joystick axes and buttons drive the robot (robot profile ``joystick:``).

    Numbers are the Linux joystick API's (``jstest /dev/input/js0`` shows
    them). A button set to null is absent. Defaults: Xbox/PS-style pad.
    """

    # Device path of the joystick on the robot.
    device: str
    # Axis for forward speed: 1 = left stick vertical.
    linear_axis: int
    # True because the kernel reports stick-up as negative; up must mean forward.
    invert_linear: bool
    # Axis for turning: 0 = left stick horizontal.
    angular_axis: int
    # True because the kernel reports stick-left as negative; left must mean +angular (CCW).
    invert_angular: bool
    # Deadman: nothing moves unless this button is held. 4 = LB / L1.
    enable_button: int
    # Held together with enable for turbo speeds. 5 = RB / R1; null for none.
    turbo_button: Optional[int]
    # Emergency stop (latched by the command mux). 1 = B / circle; null for none.
    estop_button: Optional[int]
    # Clears a latched emergency stop when all are held together (a chord of two or more, never one
    # button); null for none (the generic layout: any two buttons could be triggers).
    estop_reset_buttons: Optional[tuple[int, ...]]
    # Fraction of full deflection (0..1) treated as centred; the rest is rescaled to 0..1.
    # Raise it if the robot creeps with the stick released.
    dead_zone: float
    # Seconds between attempts to reopen an unplugged joystick.
    reopen_interval_s: float
    # Layout preset: auto (by the device's name), or one of gamepad_presets.PRESETS.
    preset: str
    # The fields the profile wrote: a preset fills the others.
    explicit: frozenset = field(default=frozenset(), compare=False)

    def __post_init__(self) -> None:
        if self.estop_reset_buttons is not None:
            self.estop_reset_buttons = tuple(self.estop_reset_buttons)
        for key in ("linear_axis", "angular_axis", "enable_button", "turbo_button", "estop_button"):
            value = getattr(self, key)
            if value is not None and not 0 <= value <= 255:
                raise ValueError(f"{key} must be 0..255 (a joystick API number), got {value}")
        chord = self.estop_reset_buttons
        if chord is not None:
            if len(chord) < 2 or len(set(chord)) != len(chord) or not all(0 <= b <= 255 for b in chord):
                raise ValueError(f"estop_reset_buttons must be two or more different buttons 0..255 (a chord: one "
                                 f"button alone never clears the e-stop), got {list(chord)}")
            if self.estop_button is not None and self.estop_button in chord:
                raise ValueError("the e-stop button cannot be part of the reset chord")
        if self.linear_axis == self.angular_axis:
            raise ValueError("linear_axis and angular_axis must differ")
        buttons = [b for b in self.buttons().values()]
        if len(set(buttons)) != len(buttons):
            raise ValueError(f"each button role needs its own button, got {self.buttons()}")
        if not 0.0 <= self.dead_zone < 1.0:
            raise ValueError(f"dead_zone must be in 0..1 (exclusive of 1), got {self.dead_zone}")
        if not self.reopen_interval_s >= 0:
            raise ValueError(f"reopen_interval_s must be >= 0, got {self.reopen_interval_s}")
        from beastbt.devices.gamepad_presets import PRESETS
        if self.preset != "auto" and self.preset not in PRESETS:
            raise ValueError(f"preset must be auto or one of {', '.join(PRESETS)}, got {self.preset!r}")

    @classmethod
    def from_dict(cls, d: Any) -> "JoystickMapping":
        """Build from a profile dict; unknown keys or bad values raise ``ValueError``. Remembers what was written."""
        if isinstance(d, Mapping) and "estop_reset_button" in d:
            raise ValueError("estop_reset_button (one button) is not accepted: clearing the e-stop needs a chord, "
                             "e.g. estop_reset_buttons: [6, 7] (Back + Start), or leave it to the preset")
        mapping = dataclass_from_dict(cls, d, "joystick")
        mapping.explicit = frozenset(d or {})
        return mapping

    def for_device(self, device_name: Optional[str]) -> tuple["JoystickMapping", "GamepadPreset"]:
        """This mapping with the preset's numbers where the profile wrote none, and the preset used.

        ``preset: auto`` picks the preset by the kernel's device name
        (:func:`~beastbt.devices.gamepad_presets.preset_for_name`); the
        numbers the profile wrote win over the preset's.
        """
        from beastbt.devices.gamepad_presets import PRESETS, preset_for_name
        preset = preset_for_name(device_name) if self.preset == "auto" else PRESETS[self.preset]
        changes = {key: getattr(preset, key) for key in PRESET_KEYS if key not in self.explicit}
        return replace(self, **changes), preset

    def axes(self) -> dict[str, tuple[int, bool]]:
        """Axis name -> (axis number, inverted)."""
        return {AXIS_LINEAR: (self.linear_axis, self.invert_linear), AXIS_ANGULAR: (self.angular_axis, self.invert_angular)}

    def buttons(self) -> dict[str, int]:
        """Single-button role -> button number, for the roles that are present (the reset chord: :meth:`chord`)."""
        out = {
            BUTTON_ENABLE: self.enable_button,
            BUTTON_TURBO: self.turbo_button,
            BUTTON_ESTOP: self.estop_button,
        }
        return {k: v for k, v in out.items() if v is not None}

    def chord(self) -> tuple[int, ...]:
        """The buttons that clear a latched e-stop when all are held (empty: none)."""
        return tuple(self.estop_reset_buttons or ())

    def roles(self) -> dict[str, tuple[int, ...]]:
        """Every button role -> its button numbers (``estop_reset``: the chord)."""
        out = {name: (number,) for name, number in self.buttons().items()}
        if self.chord():
            out[BUTTON_ESTOP_RESET] = self.chord()
        return out

    def scale_axis(self, raw: int, inverted: bool) -> float:
        """Raw kernel value (-32767..32767) -> -1..1 with the dead zone removed and rescaled.

        Like ROS ``joy``: inside the dead zone reads 0; outside it the rest of
        the travel is stretched back to 0..1 so there is no jump at its edge.
        """
        x = max(-1.0, min(1.0, raw / AXIS_FULL_SCALE))
        mag = abs(x)
        if mag <= self.dead_zone:
            return 0.0
        y = (mag - self.dead_zone) / (1.0 - self.dead_zone)
        y = y if x > 0 else -y
        return -y if inverted else y

    def raw_for(self, value: float, inverted: bool) -> int:
        """The raw kernel value that :meth:`scale_axis` turns into ``value`` (-1..1)."""
        v = max(-1.0, min(1.0, value))
        if inverted:
            v = -v
        if v == 0.0:
            return 0
        mag = abs(v) * (1.0 - self.dead_zone) + self.dead_zone
        raw = int(round(mag * AXIS_FULL_SCALE))
        return raw if v > 0 else -raw


class JoystickDevice:
    """Polls a Linux joystick byte source into :class:`JoystickState` (named axes -1..1, buttons).

    ``open_device()`` opens the joystick and returns its byte source, or
    raises OSError when there is none. ``poll()`` never raises. Counters:
    ``events_read``, ``garbage_bytes``, ``disconnects``.

    ``stamp_s`` of the state is the poll time while the device is open (a
    joystick sends nothing while nobody touches it, yet its state is
    current) and the time it was lost once unplugged; ``connected`` is False
    from then on until it is reopened.
    """

    def __init__(
        self,
        open_device: Callable[[], ByteSource],
        clock: Clock,
        events: EventSink = ignore_events,
        mapping: Optional[JoystickMapping] = None,
        identify: Optional[Callable[[], JoystickMapping]] = None,
    ) -> None:
        self.open_device = open_device
        self.identify = identify
        """Called each time the device opens: the mapping for the pad now plugged in (its preset)."""
        self.clock = clock
        self.events = events
        self.mapping = mapping if mapping is not None else JoystickMapping()
        self.events_read = 0
        self.garbage_bytes = 0
        self.disconnects = 0
        self._read: Optional[ByteSource] = None
        self._buffer = bytearray()
        self._axes: dict[int, int] = {}
        self._buttons: dict[int, int] = {}
        self._ever_opened = False
        self._reported_unavailable = False
        self._next_open_s: Optional[float] = None
        self._lost_at_s = 0.0

    @property
    def connected(self) -> bool:
        """True while the joystick is open."""
        return self._read is not None

    def fileno(self) -> Optional[int]:
        """The open device's file descriptor (for ``select()``), or None (closed, or a source without one)."""
        get = getattr(self._read, "fileno", None)
        return get() if get is not None else None

    def _try_open(self, now_s: float) -> None:
        if self._next_open_s is not None and now_s < self._next_open_s:
            return
        self._next_open_s = now_s + self.mapping.reopen_interval_s
        try:
            reader = self.open_device()
        except OSError as exc:
            if not self._ever_opened and not self._reported_unavailable:
                self._reported_unavailable = True
                self.events("joystick_unavailable", f"cannot open the joystick {self.mapping.device}: {exc}")
            return
        self._read = reader
        if self.identify is not None:
            self.mapping = self.identify()  # another pad may have been plugged in: its own layout
        self._buffer.clear()  # the kernel starts a fresh stream with the initial-state burst
        self._axes.clear()
        self._buttons.clear()
        if self._ever_opened:
            self.events("joystick_reopened", f"joystick {self.mapping.device} is back")
        self._ever_opened = True

    def _lose(self, now_s: float, reason: str) -> None:
        self._read = None
        self._buffer.clear()
        # Forget everything: a deadman held when the cable went counts as released.
        self._axes.clear()
        self._buttons.clear()
        self.disconnects += 1
        self._lost_at_s = now_s
        self._next_open_s = now_s + self.mapping.reopen_interval_s
        self.events("joystick_lost", f"joystick {self.mapping.device} lost ({reason}): buttons released")

    def _valid(self, value: int, kind: int) -> bool:
        base = kind & ~JS_EVENT_INIT
        if base == JS_EVENT_BUTTON:
            return value in (0, 1)
        if base == JS_EVENT_AXIS:
            return value != -32768  # the kernel clamps to -32767..32767
        return False

    def _parse(self) -> int:
        """Consume whole events from the buffer; return the number of garbage bytes skipped."""
        buf = self._buffer
        i = 0
        garbage = 0
        while len(buf) - i >= JS_EVENT_SIZE:
            _time_ms, value, kind, number = JS_EVENT.unpack_from(buf, i)
            if not self._valid(value, kind):
                # The kernel only hands out whole events, so the stream stays aligned:
                # drop the impossible event whole rather than slide into a misreading.
                i += JS_EVENT_SIZE
                garbage += JS_EVENT_SIZE
                continue
            if kind & ~JS_EVENT_INIT == JS_EVENT_BUTTON:
                self._buttons[number] = value
            else:
                self._axes[number] = value
            self.events_read += 1
            i += JS_EVENT_SIZE
        del buf[:i]
        return garbage

    def poll(self) -> JoystickState:
        """Read what the joystick sent since the last call and return the current state."""
        now_s = self.clock.now()
        if self._read is None:
            self._try_open(now_s)
        if self._read is not None:
            try:
                # Drain a bounded number of reads: a real read returns at most one buffer.
                for _ in range(64):
                    data = self._read()
                    if not data:
                        break
                    self._buffer += data
            except OSError as exc:
                self._lose(now_s, str(exc) or type(exc).__name__)
            else:
                garbage = self._parse()
                if garbage:
                    self.garbage_bytes += garbage
                    self.events("joystick_garbage", f"skipped {garbage} byte(s) that are not joystick events")
        return self.state(now_s)

    def state(self, now_s: Optional[float] = None) -> JoystickState:
        """The current named state without reading (all released and centred when disconnected)."""
        m = self.mapping
        connected = self._read is not None
        stamp = (self.clock.now() if now_s is None else now_s) if connected else self._lost_at_s
        axes = {name: m.scale_axis(self._axes.get(num, 0), inv) if connected else 0.0 for name, (num, inv) in m.axes().items()}
        buttons = {name: connected and all(self._buttons.get(num, 0) == 1 for num in numbers)
                   for name, numbers in m.roles().items()}
        buttons.setdefault(BUTTON_ESTOP_RESET, False)  # no chord on this layout: it is never held
        return JoystickState(stamp_s=stamp, axes=axes, buttons=buttons, connected=connected)


def open_linux_joystick(path: str = "/dev/input/js0") -> ByteSource:
    """Open a Linux joystick device now (O_RDONLY | O_NONBLOCK) and return its byte source.

    The source returns the bytes ready (b"" when there are none) and raises
    OSError (typically ENODEV) once the device is gone, after closing it.
    Use ``lambda: open_linux_joystick(path)`` (or :func:`linux_joystick_opener`)
    as :class:`JoystickDevice`'s ``open_device``.
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    state = {"fd": fd}

    def read() -> bytes:
        if state["fd"] is None:
            raise OSError(errno.EBADF, f"{path} was closed")
        try:
            return os.read(state["fd"], JS_EVENT_SIZE * 64)
        except BlockingIOError:
            return b""
        except OSError:
            try:
                os.close(state["fd"])
            finally:
                state["fd"] = None
            raise

    read.fileno = lambda: state["fd"]  # type: ignore[attr-defined]  # for JoystickWatcher's select()
    return read


class JoystickWatcher:
    """A thread that calls ``wake()`` as soon as the joystick has input, so teleop need not wait for the next tick.

    It only watches (``select()`` on the device's file descriptor): the
    bytes are read by whoever polls the :class:`JoystickDevice`. After each
    wake it waits until :meth:`drained` is called (or ``hold_s`` passes), so
    unread input does not make it spin. A device whose byte source has no
    ``fileno`` (a script) is never watched.
    """

    def __init__(self, device: "JoystickDevice", wake: Callable[[], None], hold_s: float = 0.05) -> None:
        import threading
        self.device = device
        self.wake = wake
        self.hold_s = hold_s
        self.wakes = 0
        self._drained = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="joystick-watcher", daemon=True)

    def start(self) -> "JoystickWatcher":
        """Start watching; returns itself."""
        self._thread.start()
        return self

    def drained(self) -> None:
        """The input that caused the last wake has been read."""
        self._drained.set()

    def stop(self) -> None:
        """Stop the thread (within about 0.1 s)."""
        self._stop.set()
        self._drained.set()
        self._thread.join(timeout=1.0)

    def _run(self) -> None:
        import select
        while not self._stop.is_set():
            fd = self.device.fileno()
            if fd is None:
                self._stop.wait(0.05)  # unplugged: the poll reopens it
                continue
            try:
                ready, _, _ = select.select([fd], [], [], 0.1)
            except (OSError, ValueError):
                self._stop.wait(0.05)  # closed under us: it will be reopened or replaced
                continue
            if ready and not self._stop.is_set():
                self._drained.clear()
                self.wakes += 1
                self.wake()
                self._drained.wait(self.hold_s)


JSIOCGNAME_128 = 0x80806A13
"""``_IOC(_IOC_READ, 'j', 0x13, 128)``: the ioctl that reads a joystick's name, up to 128 bytes."""


def device_name(path: str) -> Optional[str]:
    """The joystick's name as the kernel gives it (JSIOCGNAME, what ``jstest`` prints), or None."""
    import fcntl
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        buf = bytearray(128)
        fcntl.ioctl(fd, JSIOCGNAME_128, buf)
        return buf.split(b"\0", 1)[0].decode("utf-8", "replace") or None
    except OSError:
        return None
    finally:
        os.close(fd)


def linux_joystick_opener(path: str = "/dev/input/js0") -> Callable[[], ByteSource]:
    """An ``open_device`` for :class:`JoystickDevice` that opens ``path`` each time it is called."""
    return lambda: open_linux_joystick(path)
