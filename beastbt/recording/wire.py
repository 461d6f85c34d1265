"""What goes down the pipe from the tick loop to the recording's writer process.

The tick loop's side of recording must cost a few microseconds: it turns
its items (ticks, events, servo commands...), a batch at a time, into bytes
with :mod:`pickle`, never into JSON or MCAP, which the writer process does
on another core. Pickling a dataclass goes through Python code per object
(``__reduce_ex__``), which is most of the cost; so each reading, pose and
command is sent as ``(class code, its __dict__)``, which the C pickler
writes by itself, and a class is announced once, by module, name and field
names, before its first instance. The arrays of fields declared as arrays
(a LiDAR scan's, a frame's pixels) go as ``(class code, the other fields,
((field, dtype, shape, raw bytes), ...))``: numpy's own pickling goes through
Python code per array and per dtype. The writer process rebuilds the same
objects (or, for a class it cannot import, such as one defined inside a
test, a stand-in dataclass of the same name and fields). Values keep their
types (a numpy scalar stays one, a frame's pixels stay an array). An item
holding a dataclass without a ``__dict__`` (slots) is pickled as it is.

A frame is ``<length: u32 LE><kind: u8><payload>``; ``length`` counts the
kind byte and the payload.
"""

from __future__ import annotations

import dataclasses
import importlib
import io
import pickle
import struct
from typing import Any, Callable, Iterator, Optional

import numpy as np

HEADER = struct.Struct("<IB")
"""Frame header: length of (kind + payload), kind."""

KIND_FLAT = 0
"""Payload: a pickled list of items, their dataclasses as ``(class code, __dict__)``."""
KIND_PICKLE = 1
"""Payload: a pickled list of items as they were (the fallback)."""
KIND_CLASS = 2
"""Payload (pickled): ``(code, module, qualified name, name, field names)``, a class's first appearance."""

_PROTOCOL = pickle.HIGHEST_PROTOCOL

_RAW_KINDS = frozenset("biuf")
"""numpy dtype kinds (bool, integers, floats) whose arrays go down the pipe as raw bytes."""

_TICK_OBJECTS = (4, 5, 6, 7, 8)
"""Positions of single dataclass values in an item (None allowed): the tick's poses and commands."""


@dataclasses.dataclass(frozen=True)
class Frame:
    """A camera frame as the recorder queues it: its description, and its pixels only when it will be recorded.

    ``stamp_s``: clock seconds; ``seq``: the camera's frame number; ``width``
    and ``height``: pixels; ``image``: the pixels (rows, columns, channels)
    or None; ``jpeg``: the camera's own JPEG of a recorded frame, when it gave one (recorded as it came).
    """

    stamp_s: float
    seq: int
    width: int
    height: int
    image: Optional[np.ndarray]
    jpeg: Optional[bytes] = None


def frame_bytes(kind: int, payload: bytes) -> bytes:
    """One frame: header and payload."""
    return HEADER.pack(len(payload) + 1, kind) + payload


class ItemEncoder:
    """The tick side: items to frames (bytes), as cheaply as Python allows."""

    def __init__(self) -> None:
        self._codes: dict[type, int] = {}
        self._arrays: dict[type, tuple[str, ...]] = {}
        """Classes with fields declared as arrays -> those fields' names (sent as raw bytes: :meth:`_object`)."""
        self._unsent: list[bytes] = []
        """Class announcements not yet handed out (they go before the next frame, whatever becomes of it)."""

    def encode(self, items: list[tuple]) -> bytes:
        """One frame holding ``items`` (a batch), after announcements of the classes not sent before.

        One pickle per batch, without the pickler's memo (items are trees,
        never cycles, and the memo's bookkeeping costs more than the repeated
        field names it saves). Raises whatever :mod:`pickle` raises for an
        item it cannot take.
        """
        try:
            flat = [self._flatten(item) for item in items]
            buffer = io.BytesIO()
            pickler = pickle.Pickler(buffer, protocol=_PROTOCOL)
            pickler.fast = True
            pickler.dump(flat)
            payload, kind = buffer.getvalue(), KIND_FLAT
        except AttributeError:  # a dataclass with slots, not a __dict__
            payload, kind = pickle.dumps(items, protocol=_PROTOCOL), KIND_PICKLE
        frame = frame_bytes(kind, payload)
        if self._unsent:
            frame = b"".join(self._unsent) + frame
            self._unsent.clear()
        return frame

    def _flatten(self, item: tuple) -> tuple:
        kind = item[0]
        if kind == "tick":
            codes = self._codes
            out = list(item)
            try:
                # A dataclass goes as (class code, its __dict__): the C pickler writes a dict by itself,
                # and each field name only once per item (its memo).
                arrays = self._arrays
                out[3] = [(codes[r.__class__], r.__dict__) if r.__class__ not in arrays else self._object(r)
                          for r in item[3]]
                for i in _TICK_OBJECTS:
                    v = item[i]
                    if v is not None:
                        out[i] = (codes[v.__class__], v.__dict__)
            except KeyError:
                obj = self._object
                out[3] = [obj(r) for r in item[3]]
                for i in _TICK_OBJECTS:
                    v = item[i]
                    out[i] = None if v is None else obj(v)
            return tuple(out)
        if kind == "servo":
            return (kind, item[1], self._object(item[2]))
        return item

    def _object(self, r: Any) -> tuple:
        cls = r.__class__
        code = self._codes.get(cls)
        if code is None:
            code = self._announce(cls)
        fields = self._arrays.get(cls)
        if fields is None:
            return (code, r.__dict__)
        # Its arrays go as raw bytes: pickling an ndarray goes through numpy's Python-level __reduce_ex__ and
        # the dtype's (13 us for a LiDAR scan's three arrays), tobytes() is a copy (2 us).
        values = dict(r.__dict__)
        raw = []
        for key in fields:
            v = values.get(key)
            if v.__class__ is np.ndarray and v.dtype.kind in _RAW_KINDS:
                raw.append((key, v.dtype.str, v.shape, v.tobytes()))
                values[key] = None
        return (code, values, tuple(raw))

    def _announce(self, cls: type) -> int:
        if not dataclasses.is_dataclass(cls):
            raise TypeError(f"not a dataclass: {cls.__name__}")
        names = tuple(f.name for f in dataclasses.fields(cls))
        code = len(self._codes)
        self._codes[cls] = code
        self._unsent.append(frame_bytes(KIND_CLASS, pickle.dumps(
            (code, cls.__module__, cls.__qualname__, cls.__name__, names), protocol=_PROTOCOL)))
        fields = tuple(f.name for f in dataclasses.fields(cls) if "ndarray" in str(f.type))
        if fields:
            self._arrays[cls] = fields
        return code


def _stand_in(name: str, names: tuple) -> type:
    """A frozen dataclass called ``name`` with fields ``names``: for a class the writer cannot import."""
    return dataclasses.make_dataclass(name, list(names), frozen=True)


def _resolve(module: str, qualname: str, name: str, names: tuple) -> type:
    """The announced class itself when it imports and has those fields; else a stand-in."""
    try:
        obj: Any = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
        if isinstance(obj, type) and dataclasses.is_dataclass(obj) and \
                tuple(f.name for f in dataclasses.fields(obj)) == tuple(names):
            return obj
    except Exception:  # a class defined in a function, or a module the writer cannot import
        pass
    return _stand_in(name, names)


class ItemDecoder:
    """The writer side: frames back to items shaped as the tick side made them."""

    def __init__(self) -> None:
        self._classes: dict[int, type] = {}
        self._buffer = bytearray()

    def feed(self, data: bytes) -> Iterator[tuple]:
        """Add bytes read from the pipe; yield every item of every frame now complete, in order."""
        buf = self._buffer
        buf.extend(data)
        pos = 0
        n = len(buf)
        size = HEADER.size
        while n - pos >= size:
            length, kind = HEADER.unpack_from(buf, pos)
            end = pos + 4 + length
            if end > n:
                break
            payload = bytes(buf[pos + size:end])
            pos = end
            yield from self._decode(kind, payload)
        del buf[:pos]

    @property
    def pending_bytes(self) -> int:
        """Bytes of an incomplete frame held back (a cut at the end of the stream)."""
        return len(self._buffer)

    def _decode(self, kind: int, payload: bytes) -> list[tuple]:
        if kind == KIND_PICKLE:
            return pickle.loads(payload)
        if kind == KIND_CLASS:
            code, module, qualname, name, names = pickle.loads(payload)
            self._classes[code] = _resolve(module, qualname, name, names)
            return []
        if kind != KIND_FLAT:
            raise ValueError(f"unknown frame kind {kind}")
        return [self._rebuild(item) for item in pickle.loads(payload)]

    def _rebuild(self, item: tuple) -> tuple:
        tag = item[0]
        obj = self._object
        if tag == "tick":
            out = list(item)
            out[3] = [obj(r) for r in item[3]]
            for i in _TICK_OBJECTS:
                if out[i] is not None:
                    out[i] = obj(out[i])
            return tuple(out)
        if tag == "servo":
            return (tag, item[1], obj(item[2]))
        return item

    def _object(self, packed: tuple) -> Any:
        code, values = packed[0], packed[1]
        obj = self._classes[code].__new__(self._classes[code])
        # Straight into __dict__: frozen dataclasses refuse setattr, and __init__ may validate or convert.
        obj.__dict__.update(values)
        if len(packed) > 2:
            # Arrays sent as raw bytes; read-only views of them (the writer only reads what it records).
            obj.__dict__.update({key: np.frombuffer(data, dtype=dtype).reshape(shape)
                                 for key, dtype, shape, data in packed[2]})
        return obj


def read_frames(read: Callable[[int], bytes], decoder: ItemDecoder, block_size: int = 1 << 20) -> Iterator[tuple]:
    """Items from a byte source (``read(n)``, ``b''`` at its end), until the end."""
    while True:
        data = read(block_size)
        if not data:
            return
        yield from decoder.feed(data)


__all__ = ["Frame", "ItemEncoder", "ItemDecoder", "frame_bytes", "read_frames", "HEADER", "KIND_FLAT",
           "KIND_PICKLE", "KIND_CLASS"]
