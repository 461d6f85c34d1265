"""Every example of the mission language doc validates: its words keep their meaning."""

from __future__ import annotations

import re

import pytest

from beastbt.core.errors import InvalidInput
from beastbt.mission.model import load_mission
from conftest import REPO

DOC = (REPO / "docs" / "mission-language.md").read_text()
EXAMPLES = [b for b in re.findall(r"```yaml\n(.*?)```", DOC, re.S) if b.lstrip().startswith(("mission:", "#"))
            and "mission:" in b]


def test_the_doc_has_its_examples():
    assert len(EXAMPLES) >= 5


@pytest.mark.parametrize("text", EXAMPLES, ids=[re.search(r"mission: (\S+)", t).group(1) for t in EXAMPLES])
def test_example_validates(text, tmp_path):
    path = tmp_path / "example.yaml"
    path.write_text(text)
    try:
        load_mission(path)
    except InvalidInput as exc:
        pytest.fail(exc.format())


def test_failsafe_block_of_the_doc_validates(tmp_path):
    block = re.search(r"```yaml\n(failsafes:.*?)```", DOC, re.S).group(1)
    text = "mission: f\nplaces: {home2: {lat: 1, lon: 2}}\nsteps: [stop]\n" + block
    (tmp_path / "f.yaml").write_text(text)
    load_mission(tmp_path / "f.yaml")
