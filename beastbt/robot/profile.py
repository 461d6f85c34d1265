"""Robot profiles: which devices a robot has, on which ports, its geometry, limits and tuning.

A profile is a YAML file checked against ``schemas/robot.schema.json`` with
the same positioned errors as missions. ``sim`` names the built-in
simulator's profile (``robots/sim.yaml``); any other name is a path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Union

from beastbt.core.unit_fields import read_unit_values
from beastbt.behaviours.context import ControlParams
from beastbt.core.errors import InvalidInput, Position, Problem, did_you_mean
from beastbt.core.schema_defaults import schema_default
from beastbt.core.schema_check import schema_problems
from beastbt.core.yaml_source import SourceDoc, load_yaml
from beastbt.core.resources import data_dir

DEFAULT_COMMAND_TIMEOUT_S: float = schema_default("robot.schema.json#/properties/safety", "command_timeout_s")
"""No fresh command for this long means zero velocity (s): the field's watchdog figure."""


@dataclass
class RobotProfile:
    """A checked robot profile. Limits in SI (m/s, rad/s, m/s^2, rad/s^2)."""

    name: str
    file: str
    doc: SourceDoc
    data: dict
    track_width_m: float
    max_speed_mps: float
    max_turn_rate_rps: float
    max_accel_mps2: float = 1.0
    max_angular_accel_rps2: float = math.radians(360.0)
    command_timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S
    control: ControlParams = field(default_factory=ControlParams)

    def section(self, name: str) -> Optional[dict]:
        """A device section (``base``, ``gps``, ``imu``...), or None when the robot has none."""
        value = self.data.get(name)
        return dict(value) if isinstance(value, dict) else None


def profile_path(name: Union[str, Path]) -> Path:
    """Resolve ``sim`` (or another bundled profile name) or a path to a profile file."""
    p = Path(name)
    if p.suffix in (".yaml", ".yml") or p.exists():
        return p
    bundled = data_dir("robots") / f"{name}.yaml"
    return Path(str(bundled))


def load_profile(name: Union[str, Path]) -> RobotProfile:
    """Load and check a robot profile; raise :class:`InvalidInput` with every problem found."""
    path = profile_path(name)
    if not path.exists() and Path(str(name)).suffix not in (".yaml", ".yml"):
        bundled = sorted(p.stem for p in data_dir("robots").glob("*.yaml"))
        raise InvalidInput([Problem(str(name), Position(1, 1),
                                    f"no robot profile called '{name}'{did_you_mean(str(name), bundled)}",
                                    f"the bundled profiles are {', '.join(bundled)}; or give a profile's file path")])
    doc = load_yaml(path, display_name=str(name) if Path(str(name)).suffix else str(path))
    problems = read_unit_values(doc) or schema_problems(doc, "robot.schema.json", "robot profile")
    control = ControlParams()
    if not problems:
        try:
            control = ControlParams.from_dict(doc.data.get("control") or {})
        except (TypeError, ValueError) as exc:
            problems.append(doc.problem(("control",), str(exc)))
    if problems:
        raise InvalidInput(problems)
    d = doc.data
    lim = d["limits"]
    return RobotProfile(
        name=d["robot"], file=doc.file, doc=doc, data=d,
        track_width_m=float(d["geometry"]["track_width_m"]),
        max_speed_mps=float(lim["max_speed_mps"]),
        max_turn_rate_rps=math.radians(float(lim["max_turn_rate_dps"])),
        max_accel_mps2=float(lim.get("max_accel_mps2", _limit_default("max_accel_mps2"))),
        max_angular_accel_rps2=math.radians(float(lim.get("max_angular_accel_dps2", _limit_default("max_angular_accel_dps2")))),
        command_timeout_s=float((d.get("safety") or {}).get("command_timeout_s", DEFAULT_COMMAND_TIMEOUT_S)),
        control=control,
    )


def _limit_default(name: str) -> float:
    return float(schema_default("robot.schema.json#/properties/limits", name))


def section_config(profile: RobotProfile, section: str, config_cls: Any) -> Any:
    """Build ``config_cls.from_dict`` from a profile section, turning a ValueError into a positioned problem."""
    raw = profile.section(section) or {}
    try:
        return config_cls.from_dict(raw)
    except (TypeError, ValueError) as exc:
        raise InvalidInput([profile.doc.problem((section,), f"in '{section}': {exc}",
                                                "see the schema in schemas/ for the knobs this section takes")])
