"""The mission's values and the blackboard's readings compare, hash, print and stay frozen as
``@dataclass(frozen=True)`` would make them.

:class:`beastbt.core.values.Value` and :class:`~beastbt.core.values.Compared` write those
methods once instead of letting ``@dataclass`` compile them for each of ~65 classes
(start-up time). Each class is checked here against a twin made by the standard
library's ``@dataclass(frozen=True, kw_only=True)`` with the same fields and values.
"""

from __future__ import annotations

import dataclasses

import pytest

from beastbt.blackboard import types as bb
from beastbt.core.errors import Position
from beastbt.core.values import Compared, Value
from beastbt.mission import steps as st
from beastbt.mission.external_steps import ExternalStep
from beastbt.mission.model import Failsafe, Place, RawStep

CLASSES = sorted([c for module in (st, bb) for c in vars(module).values()
                  if isinstance(c, type) and issubclass(c, Compared) and c not in (Compared, Value)
                  and dataclasses.is_dataclass(c)] + [Place, RawStep, Failsafe, ExternalStep],
                 key=lambda c: c.__name__)


def _twin(cls: type) -> type:
    """A standard frozen, keyword-only dataclass with ``cls``'s name and fields (no defaults: all are given)."""
    namespace = {"__annotations__": {f.name: f.type for f in dataclasses.fields(cls)},
                 "__qualname__": cls.__qualname__}
    return dataclasses.dataclass(frozen=True, kw_only=True)(type(cls.__name__, (), namespace))


def _values(cls: type, salt: int) -> dict:
    """A value for every field of ``cls`` (``salt`` makes a different set), nested values included."""
    out: dict = {}
    for i, f in enumerate(dataclasses.fields(cls)):
        if f.name == "at":
            out[f.name] = Position(3 + salt, 4)
        elif f.name == "path":
            out[f.name] = ("steps", salt, "repeat")
        elif i % 3 == 0:
            out[f.name] = st.Flag(word=f"w{salt}")
        elif i % 3 == 1:
            out[f.name] = 1.5 + salt
        else:
            out[f.name] = (f"text '{salt}'", None)
    return out


def test_every_step_and_condition_class_is_checked() -> None:
    names = {c.__name__ for c in CLASSES}
    assert {"Step", "DriveDistance", "GoToPlace", "Flag", "AnyOf", "PluginStep", "NavOptions", "Place"} <= names
    assert set(c.__name__ for c in st.CORE_STEP_CLASSES) <= names
    assert {"GpsFix", "ImuSample", "JoystickState", "LaserScan", "VelocityCommand", "LocalPlan"} <= names


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_eq_hash_repr_as_a_frozen_dataclass(cls: type) -> None:
    twin = _twin(cls)
    one, same, other = _values(cls, 0), _values(cls, 0), _values(cls, 1)
    assert repr(cls(**one)) == repr(twin(**one))
    assert hash(cls(**one)) == hash(twin(**one)) == hash(cls(**same))
    assert cls(**one) == cls(**same) and not cls(**one) != cls(**same)
    if other != one:
        assert cls(**one) != cls(**other)
    assert cls(**one) != twin(**one)  # another class with the same fields is not equal, as with dataclasses
    assert len({cls(**one), cls(**same)}) == 1
    first = dataclasses.fields(cls)[0].name
    for value in (cls(**one), twin(**one)):
        with pytest.raises(dataclasses.FrozenInstanceError, match=f"cannot assign to field '{first}'"):
            setattr(value, first, 2.0)
        with pytest.raises(dataclasses.FrozenInstanceError, match="cannot assign to field 'extra'"):
            value.extra = 1  # type: ignore[attr-defined]
        with pytest.raises(dataclasses.FrozenInstanceError, match=f"cannot delete field '{first}'"):
            delattr(value, first)
    assert dataclasses.replace(cls(**one), **{first: one[first]}) == cls(**one)
    assert dataclasses.astuple(cls(**one)) == dataclasses.astuple(twin(**one))


def test_a_recursive_value_prints_without_recursing() -> None:
    inner: list = []
    step = st.PluginStep(keyword="x", value=inner)
    inner.append(step)
    assert repr(step) == "PluginStep(at=Position(line=1, column=1), path=(), keyword='x', value=[...])"


def test_steps_of_different_classes_with_the_same_fields_differ() -> None:
    assert st.TurnBy(angle_rad=1.0) != st.TurnToHeading(heading_rad=1.0)
    assert st.Flag(word="gps_fix") != st.Not(condition=st.Flag(word="gps_fix"))
    assert dataclasses.replace(st.Wait(duration_s=2.0), duration_s=3.0) == st.Wait(duration_s=3.0)


def test_classes_with_no_field_or_one_field_hash_as_dataclasses() -> None:
    @dataclasses.dataclass(frozen=True, eq=False, repr=False)
    class Empty(Compared):
        pass

    @dataclasses.dataclass(eq=False, repr=False)
    class One(Value):
        x: float

    @dataclasses.dataclass(frozen=True)
    class EmptyTwin:
        pass

    @dataclasses.dataclass(frozen=True)
    class OneTwin:
        x: float

    assert hash(Empty()) == hash(EmptyTwin()) and Empty() == Empty()
    assert repr(Empty()) == repr(EmptyTwin()).replace("EmptyTwin", "Empty")  # the qualified name, as a dataclass
    assert hash(One(2.5)) == hash(OneTwin(2.5)) and One(2.5) != One(3.0)
    assert repr(One(2.5)) == repr(OneTwin(2.5)).replace("OneTwin", "One")
