"""What ``@dataclass`` generates for a value class, written once for many classes (start-up time).

``@dataclass`` generates the methods of each class as Python source and
compiles it, one ``exec`` per method per class (Python 3.11): a frozen class
costs six, about a third of a millisecond on a desktop and more on a Pi. With
a hundred such classes loaded by every ``beastbt`` command, that was a tenth
of ``beastbt tree``'s start-up. The classes below give the same methods, with
the same results, once:

* :class:`Compared`: ``==``, ``hash()`` and ``repr()``, for a class decorated
  ``@dataclass(frozen=True, eq=False, repr=False)`` (still frozen by the
  dataclass: it is made often, and the dataclass's ``__init__`` is the fastest);
* :class:`Value`: those and the freezing itself, for a class decorated
  ``@dataclass(eq=False, repr=False)`` that is made rarely (a mission's steps).

As a dataclass's: equal when of the same class with equal fields, in order;
the hash of the fields' tuple; ``Name(field=value, ...)`` (``...`` where a
value contains itself); :class:`~dataclasses.FrozenInstanceError` on setting or
deleting any attribute once ``__init__`` has set each field.
"""

from __future__ import annotations

from dataclasses import FrozenInstanceError, fields
from operator import attrgetter
from reprlib import recursive_repr
from typing import Any, Callable

_COMPARED: dict[type, Callable[[Any], tuple]] = {}
_REPRS: dict[type, tuple[str, ...]] = {}
_NAMES: dict[type, frozenset[str]] = {}


def _compared(cls: type) -> Callable[[Any], tuple]:
    """A function giving the tuple of an instance's compared fields, in order (made once per class)."""
    get = _COMPARED.get(cls)
    if get is None:
        names = [f.name for f in fields(cls) if f.compare]  # type: ignore[arg-type]
        if len(names) >= 2:
            get = attrgetter(*names)
        elif names:
            one = attrgetter(names[0])
            get = lambda value: (one(value),)  # noqa: E731 - a tuple, as the dataclass compares and hashes
        else:
            get = lambda value: ()  # noqa: E731
        _COMPARED[cls] = get
    return get


class Compared:
    """``==``, ``hash()`` and ``repr()`` as ``@dataclass(frozen=True)`` makes them (see the module's docstring)."""

    __slots__ = ()

    def __eq__(self, other: object) -> bool:
        if other.__class__ is self.__class__:
            get = _compared(self.__class__)
            return get(self) == get(other)
        return NotImplemented

    def __hash__(self) -> int:
        return hash(_compared(self.__class__)(self))

    @recursive_repr()
    def __repr__(self) -> str:
        cls = self.__class__
        names = _REPRS.get(cls)
        if names is None:
            names = _REPRS[cls] = tuple(f.name for f in fields(cls) if f.repr)  # type: ignore[arg-type]
        shown = ", ".join(f"{name}={getattr(self, name)!r}" for name in names)
        return f"{cls.__qualname__}({shown})"


class Value(Compared):
    """:class:`Compared`, and frozen as ``@dataclass(frozen=True)`` makes a class (see the module's docstring)."""

    __slots__ = ()

    def __setattr__(self, name: str, value: Any) -> None:
        # The dataclass's own __init__ sets each field once; nothing else may set anything, ever.
        cls = self.__class__
        names = _NAMES.get(cls)
        if names is None:
            names = _NAMES[cls] = frozenset(f.name for f in fields(cls))  # type: ignore[arg-type]
        if name in self.__dict__ or name not in names:
            raise FrozenInstanceError(f"cannot assign to field {name!r}")
        object.__setattr__(self, name, value)

    def __delattr__(self, name: str) -> None:
        raise FrozenInstanceError(f"cannot delete field {name!r}")
