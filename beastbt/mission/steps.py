"""The steps and conditions of the mission language as typed values: one frozen dataclass each, SI units.

Each is ``@dataclass(kw_only=True, eq=False, repr=False)`` on :class:`beastbt.core.values.Value`, which freezes,
compares, hashes and prints it as ``@dataclass(frozen=True)`` would, with fewer methods compiled at start-up.

The loader (:mod:`beastbt.mission.model`) turns what the author wrote into
these; the compiler (:mod:`beastbt.mission.compile`) turns each into a
behaviour. Every step knows where it was written (``at``: line and column in
the mission file; ``path``: its place in the document) and its keyword
(``KEYWORD``). Quantities are SI floats with the unit in the field's name;
an optional field the author left out is None, and the behaviour then uses
the robot's default. Nested steps are tuples.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Optional, Union

from beastbt.core.errors import Position
from beastbt.core.values import Value
from beastbt.core.yaml_source import PathKey

FOREVER = -1
"""``times``/``loops`` of ``forever``."""


@dataclass(kw_only=True, eq=False, repr=False)
class Step(Value):
    """What every step has: where it was written."""

    KEYWORD: ClassVar[str] = ""
    at: Position = Position()
    """Line and column of the step in the mission file."""
    path: PathKey = ()
    """The step's place in the mission document (``("steps", 2)``)."""


# -- motion -----------------------------------------------------------------------------------------------

@dataclass(kw_only=True, eq=False, repr=False)
class DriveDistance(Step):
    """``drive: {distance: 3 m}``: drive straight for a distance (negative: backwards), by odometry."""

    KEYWORD: ClassVar[str] = "drive"
    distance_m: float
    speed_mps: Optional[float] = None
    stuck_after_s: Optional[float] = None


@dataclass(kw_only=True, eq=False, repr=False)
class DriveTime(Step):
    """``drive: {time: 2 s}``: drive straight for a time."""

    KEYWORD: ClassVar[str] = "drive"
    duration_s: float
    speed_mps: Optional[float] = None


@dataclass(kw_only=True, eq=False, repr=False)
class TurnBy(Step):
    """``turn: {angle: 90 deg}``: turn in place by an angle (positive: left)."""

    KEYWORD: ClassVar[str] = "turn"
    angle_rad: float
    rate_rps: Optional[float] = None
    stuck_after_s: Optional[float] = None


@dataclass(kw_only=True, eq=False, repr=False)
class TurnToHeading(Step):
    """``turn: {heading: 90 deg}``: turn in place to a compass heading (0 north, 90 east)."""

    KEYWORD: ClassVar[str] = "turn"
    heading_rad: float
    rate_rps: Optional[float] = None
    stuck_after_s: Optional[float] = None


@dataclass(kw_only=True, eq=False, repr=False)
class Wait(Step):
    """``wait: 2 s``: stand still for a time."""

    KEYWORD: ClassVar[str] = "wait"
    duration_s: float


@dataclass(kw_only=True, eq=False, repr=False)
class Stop(Step):
    """``stop``: command zero and wait until the robot is still."""

    KEYWORD: ClassVar[str] = "stop"


@dataclass(kw_only=True, eq=False, repr=False)
class NavOptions(Value):
    """What go_to, route and return_home share; None: the robot's navigation defaults."""

    tolerance_m: Optional[float] = None
    speed_mps: Optional[float] = None
    gps_timeout_s: Optional[float] = None
    stuck_after_s: Optional[float] = None
    blocked_after_s: Optional[float] = None
    """With a LiDAR: fail after this long kept from progress by obstacles (s); None: the robot's default."""
    recovery_tries: Optional[int] = None
    """With a LiDAR: recoveries before giving up (``recovery: {tries: N}``; 0 for ``recovery: none``); None: the
    robot's ``recovery.tries``."""


@dataclass(kw_only=True, eq=False, repr=False)
class GoToPlace(Step, NavOptions):
    """``go_to: gate``: drive to a named place (``home`` included)."""

    KEYWORD: ClassVar[str] = "go_to"
    place: str


@dataclass(kw_only=True, eq=False, repr=False)
class GoToPoint(Step, NavOptions):
    """``go_to: {lat: 40.4168, lon: -3.7038}``: drive to a WGS84 point (degrees)."""

    KEYWORD: ClassVar[str] = "go_to"
    lat_deg: float
    lon_deg: float


@dataclass(kw_only=True, eq=False, repr=False)
class Route(Step, NavOptions):
    """``route: {places: [a, b, c], loops: 2}``: go to each place in order, ``loops`` times (-1: forever)."""

    KEYWORD: ClassVar[str] = "route"
    places: tuple[str, ...]
    loops: int = 1
    resume: str = "current"
    """After a pause: ``current`` place, or the ``nearest`` remaining one."""
    at_each: tuple["Step", ...] = ()
    """Steps run at each place once reached (``at_each``); a bare ``photo`` is named after the place."""
    stop_on_failure: bool = True
    """False: a place that fails is noted and the route goes on (``stop_on_failure: false``)."""


@dataclass(kw_only=True, eq=False, repr=False)
class ReturnHome(Step, NavOptions):
    """``return_home``: drive back to where the mission started (its first good GPS fix)."""

    KEYWORD: ClassVar[str] = "return_home"
    along: str = "straight"
    """``straight`` home, or ``path``: back along the path driven so far."""


@dataclass(kw_only=True, eq=False, repr=False)
class FollowLine(Step):
    """``follow_line: {until: intersection}``: follow the line on the floor until something happens.

    ``until`` is ``intersection``, ``line_end``, ``distance`` or ``time``;
    ``amount`` is the distance (m) or the time (s) of the last two.
    """

    KEYWORD: ClassVar[str] = "follow_line"
    until: str
    amount: Optional[float] = None
    speed_mps: Optional[float] = None
    lost_after_s: Optional[float] = None


# -- the camera, servos, the operator ---------------------------------------------------------------------

@dataclass(kw_only=True, eq=False, repr=False)
class Look(Step):
    """``look: {pan: -45 deg, tilt: 10 deg}``: point the camera's gimbal."""

    KEYWORD: ClassVar[str] = "look"
    pan_rad: Optional[float] = None
    tilt_rad: Optional[float] = None
    settle_s: Optional[float] = None


@dataclass(kw_only=True, eq=False, repr=False)
class ServoAngle(Step):
    """``servo: {name: arm, angle: 30 deg}``: move a named servo to an angle."""

    KEYWORD: ClassVar[str] = "servo"
    name: str
    angle_rad: float
    settle_s: Optional[float] = None


@dataclass(kw_only=True, eq=False, repr=False)
class ServoPulse(Step):
    """``servo: {channel: 1, pulse: 1.5 ms}``: send a raw pulse width to a PWM channel."""

    KEYWORD: ClassVar[str] = "servo"
    channel: int
    pulse_s: float
    settle_s: Optional[float] = None


@dataclass(kw_only=True, eq=False, repr=False)
class Snapshot(Step):
    """``snapshot: {name: gate}``: save a camera frame into the run folder."""

    KEYWORD: ClassVar[str] = "snapshot"
    name: str


@dataclass(kw_only=True, eq=False, repr=False)
class Say(Step):
    """``say: text``: log a message (and show it to the operator)."""

    KEYWORD: ClassVar[str] = "say"
    text: str


@dataclass(kw_only=True, eq=False, repr=False)
class Teleop(Step):
    """``teleop: {for: 30 s}`` or ``teleop: {until: released}``: hand the robot to the joystick's operator."""

    KEYWORD: ClassVar[str] = "teleop"
    duration_s: Optional[float] = None
    """None: until the operator releases the enable button."""


@dataclass(kw_only=True, eq=False, repr=False)
class Photo(Step):
    """``photo: {name: gate}`` (or ``photo``): save the camera's frame at full resolution; ``name`` None: named after
    where it was taken."""

    KEYWORD: ClassVar[str] = "photo"
    name: Optional[str] = None


@dataclass(kw_only=True, eq=False, repr=False)
class Alert(Step):
    """``alert: "someone in the lab"`` (``{text, photo: true}``): an event of kind alert, with a photo when asked."""

    KEYWORD: ClassVar[str] = "alert"
    text: str
    photo: bool = False


@dataclass(kw_only=True, eq=False, repr=False)
class Dock(Step):
    """``dock: {tag: 0, distance: 0.25 m}``: staging pose 1 m in front of the tag, a visual approach to ``distance_m``
    (robot centre to the tag's face), square to it. ``size_m``: the tag's black square (m)."""

    KEYWORD: ClassVar[str] = "dock"
    tag: int
    distance_m: float
    size_m: float
    family: str
    speed_mps: Optional[float] = None


@dataclass(kw_only=True, eq=False, repr=False)
class Undock(Step):
    """``undock`` (``{distance: 0.5 m}``): back straight off the dock."""

    KEYWORD: ClassVar[str] = "undock"
    distance_m: float


@dataclass(kw_only=True, eq=False, repr=False)
class Track(Step):
    """``track: {colour: red, for: 30 s}``: turn to keep the largest blob of a colour centred, for a time."""

    KEYWORD: ClassVar[str] = "track"
    colour: Any
    duration_s: float


@dataclass(kw_only=True, eq=False, repr=False)
class Ros2Goals(Step):
    """``ros2_goals: {goals: 3, for: 10 min, until: CONDITION}``: drive to each goal ROS 2 sends on ``/goal_pose``
    (rviz2's 2D Goal Pose), planned on the mission's map; each option left out does not end the step."""

    KEYWORD: ClassVar[str] = "ros2_goals"
    goals: Optional[int] = None
    """Succeed once this many goals are reached."""
    duration_s: Optional[float] = None
    """Succeed once this long has passed (a goal under way is given up)."""
    until: Optional["Condition"] = None
    """Succeed once this holds."""
    tolerance_m: Optional[float] = None
    speed_mps: Optional[float] = None


# -- conditions --------------------------------------------------------------------------------------------

@dataclass(kw_only=True, eq=False, repr=False)
class Flag(Value):
    """A condition word: ``intersection``, ``line_seen``, ``gps_fix``, ``teleop_active``, ``localized``."""

    word: str


@dataclass(kw_only=True, eq=False, repr=False)
class BatteryBelow(Value):
    """``{battery_below: 11 V}``."""

    volts: float


@dataclass(kw_only=True, eq=False, repr=False)
class Near(Value):
    """``{near: gate, within: 3 m}``: the fused position is within ``within_m`` of a place (``home`` included)."""

    place: str
    within_m: float


@dataclass(kw_only=True, eq=False, repr=False)
class Elapsed(Value):
    """``{elapsed: 10 min}``: mission time since the start, s."""

    duration_s: float


@dataclass(kw_only=True, eq=False, repr=False)
class Not(Value):
    """``{not: CONDITION}``."""

    condition: "Condition"


@dataclass(kw_only=True, eq=False, repr=False)
class AllOf(Value):
    """``{all: [CONDITION, ...]}``."""

    conditions: tuple["Condition", ...]


@dataclass(kw_only=True, eq=False, repr=False)
class AnyOf(Value):
    """``{any: [CONDITION, ...]}``."""

    conditions: tuple["Condition", ...]


@dataclass(kw_only=True, eq=False, repr=False)
class DistanceTravelled(Value):
    """``{distance_travelled: 5 m}``: odometry distance since the enclosing guard block started, m."""

    distance_m: float


@dataclass(kw_only=True, eq=False, repr=False)
class TimeInBlock(Value):
    """``{time_in_block: 30 s}``: time since the enclosing guard block started, s."""

    duration_s: float


@dataclass(kw_only=True, eq=False, repr=False)
class Answered(Value):
    """``{answered: ID, is: yes|no}``: the question ``ID`` was answered so."""

    question_id: str
    choice: str


@dataclass(kw_only=True, eq=False, repr=False)
class InFence(Value):
    """``{inside: FENCE}`` / ``{outside: FENCE}``: where the fused position is with respect to a fence."""

    fence: str
    inside: bool


@dataclass(kw_only=True, eq=False, repr=False)
class ObstacleWithin(Value):
    """``{obstacle_within: 0.5 m, sector_deg: [-30, 30]}``: the LiDAR sees something within ``gap_m`` of the
    footprint (free space, m), in the sector from ``sector_rad[0]`` counterclockwise to ``sector_rad[1]`` (base_link,
    rad, 0 ahead) or all around (None)."""

    gap_m: float
    sector_rad: Optional[tuple[float, float]] = None


@dataclass(kw_only=True, eq=False, repr=False)
class Sees(Value):
    """``{sees: ...}``: the camera sees ``what`` now: ``tag`` (``tag_id`` of ``family``, within ``within_m`` when
    given, measured for a black square of ``size_m``), ``qr`` (``text``), ``motion``, or ``colour`` (``colour`` as written, at least ``min_area_frac`` of the
    picture)."""

    what: str
    tag_id: Optional[int] = None
    family: Optional[str] = None
    within_m: Optional[float] = None
    text: Optional[str] = None
    colour: Any = None
    min_area_frac: float = 0.01
    size_m: Optional[float] = None  # the tag's black square (m), when the mission says it


Condition = Union[Flag, BatteryBelow, Near, Elapsed, Not, AllOf, AnyOf, DistanceTravelled, TimeInBlock, Answered,
                  InFence, ObstacleWithin, Sees]
"""A condition of ``if``, ``while``, ``wait_until``, ``until`` and ``abort_if``."""


# -- flow ---------------------------------------------------------------------------------------------------

@dataclass(kw_only=True, eq=False, repr=False)
class Repeat(Step):
    """``repeat: {times: 3, steps: [...]}``: run the steps ``times`` times (-1: forever); fails when they fail."""

    KEYWORD: ClassVar[str] = "repeat"
    times: int
    steps: tuple[Step, ...]


@dataclass(kw_only=True, eq=False, repr=False)
class Retry(Step):
    """``retry: {times: 3, steps: [...]}``: run the steps until they succeed, at most ``times`` attempts."""

    KEYWORD: ClassVar[str] = "retry"
    times: int
    steps: tuple[Step, ...]


@dataclass(kw_only=True, eq=False, repr=False)
class Timeout(Step):
    """``timeout: {after: 2 min, steps: [...]}``: the steps fail when they take longer than ``after_s``."""

    KEYWORD: ClassVar[str] = "timeout"
    after_s: float
    steps: tuple[Step, ...]


@dataclass(kw_only=True, eq=False, repr=False)
class Parallel(Step):
    """``parallel: {steps: [...], succeed_on: all|one}``: run the steps together."""

    KEYWORD: ClassVar[str] = "parallel"
    succeed_on: str
    steps: tuple[Step, ...]


@dataclass(kw_only=True, eq=False, repr=False)
class FirstOf(Step):
    """``first_of: [[...], [...]]``: try each list of steps in turn until one succeeds."""

    KEYWORD: ClassVar[str] = "first_of"
    alternatives: tuple[tuple[Step, ...], ...]


@dataclass(kw_only=True, eq=False, repr=False)
class Do(Step):
    """``do: task``: run a task of the mission by name."""

    KEYWORD: ClassVar[str] = "do"
    task: str
    args: tuple = ()
    """``(parameter, value as written)`` pairs of ``do: {task, ...}``, sorted; empty: the task's defaults."""


@dataclass(kw_only=True, eq=False, repr=False)
class If(Step):
    """``if: CONDITION, then: [...], else: [...]``: choose once, when the step starts."""

    KEYWORD: ClassVar[str] = "if"
    condition: Condition
    then: tuple[Step, ...]
    otherwise: Optional[tuple[Step, ...]] = None


@dataclass(kw_only=True, eq=False, repr=False)
class While(Step):
    """``while: CONDITION, steps: [...]``: run the steps again and again while the condition holds."""

    KEYWORD: ClassVar[str] = "while"
    condition: Condition
    steps: tuple[Step, ...]


@dataclass(kw_only=True, eq=False, repr=False)
class UntilBlock(Step):
    """``until: CONDITION, steps: [...]``: run the steps; when the condition holds, halt them and succeed."""

    KEYWORD: ClassVar[str] = "until"
    condition: Condition
    steps: tuple[Step, ...]


@dataclass(kw_only=True, eq=False, repr=False)
class AbortIf(Step):
    """``abort_if: CONDITION, steps: [...]``: run the steps; when the condition holds, halt them and fail."""

    KEYWORD: ClassVar[str] = "abort_if"
    condition: Condition
    steps: tuple[Step, ...]


@dataclass(kw_only=True, eq=False, repr=False)
class Ask(Step):
    """``ask: {id, question, timeout, default}, then: [...], else: [...]``: ask the operator yes or no, then choose."""

    KEYWORD: ClassVar[str] = "ask"
    question_id: str
    question: str
    timeout_s: Optional[float] = None
    default: Optional[str] = None
    """``yes``/``no``: the answer when the timeout passes."""
    then: tuple[Step, ...] = ()
    otherwise: tuple[Step, ...] = ()


@dataclass(kw_only=True, eq=False, repr=False)
class WaitUntil(Step):
    """``wait_until: CONDITION, timeout: 30 s``: stand still until the condition holds (fails after the timeout)."""

    KEYWORD: ClassVar[str] = "wait_until"
    condition: Condition
    timeout_s: Optional[float] = None


@dataclass(kw_only=True, eq=False, repr=False)
class PluginStep(Step):
    """A step of an installed package (``beastbt.steps`` entry points): its keyword and its value as written."""

    keyword: str
    value: Any


CORE_STEP_CLASSES: tuple[type[Step], ...] = (
    DriveDistance, DriveTime, TurnBy, TurnToHeading, Wait, Stop, GoToPlace, GoToPoint, Route, ReturnHome, FollowLine,
    Look, ServoAngle, ServoPulse, Snapshot, Say, Teleop, Repeat, Retry, Timeout, Parallel, FirstOf, Do, If, While,
    WaitUntil, UntilBlock, AbortIf, Ask, Photo, Alert, Dock, Undock, Track, Ros2Goals,
)
"""Every step class of the language (not PluginStep)."""


def keyword_of(step: Step) -> str:
    """The step's keyword as written (``drive``; a package's own for a PluginStep)."""
    return step.keyword if isinstance(step, PluginStep) else step.KEYWORD


__all__ = [c.__name__ for c in CORE_STEP_CLASSES] + [
    "Value", "Step", "NavOptions", "PluginStep", "Condition", "Flag", "BatteryBelow", "Near", "Elapsed", "Not", "AllOf",
    "AnyOf", "DistanceTravelled", "TimeInBlock", "Answered", "InFence", "Sees", "CORE_STEP_CLASSES", "FOREVER", "keyword_of"]
