"""Stable node ids: paths from the root, the same for every run, distinct for steps that share a name."""

from beastbt.run.tree_ids import node_ids, tree_layout
from beastbt.testing import MissionHarness

MISSION = """
mission: twice
steps:
  - drive: {distance: 0.2 m}
  - repeat:
      times: 2
      steps:
        - drive: {distance: 0.2 m}
        - wait: 0.1 s
"""


def test_ids_are_paths_parents_first_and_distinct_for_shared_names() -> None:
    h = MissionHarness.from_yaml(MISSION)
    layout = tree_layout(h.run.root)
    ids = [n.id for n in layout]
    assert ids[0] == "0" and layout[0].parent is None
    assert len(set(ids)) == len(ids) == len(h.run.nodes)
    seen = set()
    for n in layout:
        assert n.parent is None or n.parent in seen  # parents come first
        seen.add(n.id)
    drives = [n for n in layout if n.name.startswith("drive")]
    assert len(drives) == 2 and drives[0].id != drives[1].id
    kinds = {n.kind for n in layout}
    assert "action" in kinds and ({"sequence", "decorator"} & kinds)


def test_ids_are_the_same_for_every_run_of_a_mission() -> None:
    a = [n.as_dict() for n in tree_layout(MissionHarness.from_yaml(MISSION).run.root)]
    b = [n.as_dict() for n in tree_layout(MissionHarness.from_yaml(MISSION).run.root)]
    assert a == b
    root = MissionHarness.from_yaml(MISSION).run.root
    assert set(node_ids(root).values()) == {n["id"] for n in a}
