"""The camera examples of docs/mission-language.md run on the simulator in their worlds and do what they say."""

from __future__ import annotations

import re

import pytest

from beastbt.testing import MissionHarness
from conftest import REPO

DOC = (REPO / "docs" / "mission-language.md").read_text(encoding="utf-8")
CAMERA_EXAMPLES = {re.search(r"mission: (\S+)", b).group(1): b for b in re.findall(r"```yaml\n(.*?)```", DOC, re.S)
                   if b.startswith("mission: camera_")}
EXPECTED = {
    # mission -> the kinds of event it must make, in order (of those listed here)
    "camera_watch": ["photo", "photo", "alert"],
    "camera_rounds": ["photo", "photo", "alert", "docked"],
    "camera_checkpoint": ["say"],
    "camera_patrol": ["photo", "photo", "photo"],
}


def test_the_doc_has_the_camera_examples():
    assert sorted(CAMERA_EXAMPLES) == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_camera_example_runs(name):
    h = MissionHarness.from_yaml(CAMERA_EXAMPLES[name], seed=1, base_dir=REPO / "missions")
    assert h.prepared.world is not None and h.prepared.world.name == ("campus" if name == "camera_patrol" else "lab")
    assert h.run_to_end(900) == "success", [e.text for e in h.events if e.kind == "step_failed"]
    kinds = [e.kind for e in h.events if e.kind in ("photo", "alert", "docked", "say")]
    assert kinds == EXPECTED[name]
    s = h.summary()
    assert s["truth"]["collisions"] == 0
    if name == "camera_rounds":
        assert s["truth"]["dock_error_m"] < 0.02 and s["truth"]["dock_error_deg"] < 2.0
    if name == "camera_watch":
        # the caretaker walks in from 30 s on: the alert comes then, not before
        alert = next(e for e in h.events if e.kind == "alert")
        assert 30.0 < alert.time_s < 40.0
