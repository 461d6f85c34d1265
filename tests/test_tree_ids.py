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


def test_the_run_reports_each_change_with_the_nodes_stable_id() -> None:
    h = MissionHarness.from_yaml(MISSION)
    layout = {n.id: n for n in tree_layout(h.run.root)}
    assert [n.as_dict() for n in h.run.layout] == [n.as_dict() for n in layout.values()]
    h.tick(200)
    changes = [c for r in h.records for c in r.changed_nodes]
    assert changes and all(layout[node_id].name == name for name, _, _, node_id in changes)
    drives = {node_id for name, status, _, node_id in changes if name.startswith("drive") and status == "SUCCESS"}
    assert len(drives) == 2  # the first drive and the one in the repeat: two nodes, one name


def test_a_tree_put_in_later_gets_ids_that_do_not_clash() -> None:
    import py_trees

    h = MissionHarness.from_yaml(MISSION)
    h.tick(3)
    # What a return_home does: a new tree in place of the mission's.
    leaf = py_trees.behaviours.Running(name="drive 0.2 m at 0.2 m/s")
    root = py_trees.decorators.Repeat(name="instead", child=leaf, num_success=-1)
    h.run.root, h.run.nodes = root, list(root.iterate())
    h.tick(2)
    changes = {node_id: name for r in h.records[3:] for name, _, _, node_id in r.changed_nodes}
    assert changes == {"1": "instead", "1.0": "drive 0.2 m at 0.2 m/s"}
    listed = {n.id: n for n in h.run.layout}
    assert listed["1.0"].parent == "1" and listed["1"].parent is None and "0.0" in listed
