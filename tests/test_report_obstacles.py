"""``beastbt report`` on runs with obstacles: the map draws them and the persons' walks, and a clearance plot
shows the simulator's truth beside the LiDAR's nearest return, with the collisions marked."""

from __future__ import annotations

import numpy as np
import pytest

from beastbt.recording.report import DPI, FIG_SIZE_IN, MAP_SIZE_IN, RunData, draw_path, plot_clearance, plot_path
from recording_support import GPS_ROUTE, PATROL, REPO, assert_real_plot, record_run, rude_person_world

STAND = "mission: stand\nsteps:\n  - wait: 16 s\n"
"""The robot stands in the corridor; the person (from 5 s, 0.8 m/s, from x 9.5 m) walks into it at about 15 s."""




@pytest.fixture(scope="module")
def person(tmp_path_factory):
    return record_run(PATROL, tmp_path_factory.mktemp("runs"), seed=2, mission_text=STAND,
                      world=rude_person_world(tmp_path_factory.mktemp("world")))


def test_the_clearance_plot_has_the_truth_the_lidar_and_the_collision(person, tmp_path):
    folder, summary = person
    d = RunData.load(str(folder))
    assert plot_clearance(d, tmp_path / "clearance.png") is None
    assert_real_plot(tmp_path / "clearance.png", FIG_SIZE_IN, DPI)
    t_true, true = d.true_clearance()
    assert min(true) == pytest.approx(summary["truth"]["min_clearance_m"], abs=0.02)
    assert true[0] == pytest.approx(0.85, abs=0.01)  # the corridor's walls, 1 m away, less the 0.15 m footprint
    hits = d.collisions()
    assert len(hits) == summary["truth"]["collisions"] == 1
    t_hit, (x, y) = hits[0]
    assert 13.0 < t_hit < 16.0 and (x, y) == pytest.approx((1.0, 0.0), abs=0.02)  # the robot stood still
    # What the LiDAR measured agrees with the truth while nothing touches (its noise is centimetres).
    t_scan, scan = d.scan_clearance()
    before = [(t, g) for t, g in zip(t_scan, scan) if t < t_hit - 0.5]
    truth_then = np.interp([t for t, _ in before], t_true, true)
    assert len(before) > 50
    assert np.median(np.abs(np.array([g for _, g in before]) - truth_then)) < 0.04


def test_the_map_draws_the_persons_path_its_walk_and_the_collision(person):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    folder, _ = person
    d = RunData.load(str(folder))
    (walk,) = d.person_walks()
    assert walk[0] == (9.5, 0.3) and walk[-1][0] < 1.6  # from the east end up to the robot
    fig, ax = plt.subplots()
    labels = draw_path(d, ax)
    plt.close(fig)
    assert {"person's path", "person walked", "person at the end", "collision (1)"} <= set(labels)
    assert "obstacles" not in labels  # this world has no boxes or posts


def test_boxes_and_posts_are_drawn_where_the_world_has_them(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    folder, _ = record_run(GPS_ROUTE, tmp_path, seed=1, max_time_s=2.0,
                           world=str(REPO / "worlds" / "campus_obstacles.yaml"))
    d = RunData.load(str(folder))
    fixed = [o for o in d.obstacles() if o["shape"] != "person"]
    assert fixed and all(o["shape"] in ("box", "cylinder") for o in fixed)
    fig, ax = plt.subplots()
    labels = draw_path(d, ax)
    drawn = [p for p in ax.patches if p.get_label() == "obstacles" or p.get_alpha() == 0.6]
    boxes = [np.asarray(p.get_xy())[:4] for p in ax.patches if hasattr(p, "get_xy") and p.get_alpha() == 0.6]
    plt.close(fig)
    assert "obstacles" in labels and len(drawn) == len(fixed)
    corners = [np.asarray(o["corners"]) for o in fixed if o["shape"] == "box"]
    assert len(boxes) == len(corners) and all(np.allclose(a, b) for a, b in zip(boxes, corners))
    assert plot_path(d, tmp_path / "path.png") is None
    assert_real_plot(tmp_path / "path.png", MAP_SIZE_IN, DPI)


def test_on_a_real_robot_the_lidar_alone_gives_the_clearance(person, tmp_path):
    folder, _ = person
    d = RunData.load(str(folder))
    radius = float(d.rec.info["footprint_radius_m"])
    t_scan, scan = d.scan_clearance()
    # A robot's recording: no simulator truth; an older one without the radius in its metadata.
    d.rec.messages.pop("/sim/contact", None)
    d.rec.messages.pop("/truth", None)
    del d.rec.info["footprint_radius_m"]
    assert d.true_clearance() == ([], []) and d.collisions() == []
    assert d.footprint_radius_m() == pytest.approx(radius)  # from the recorded profile (robot.yaml)
    assert d.scan_clearance() == (t_scan, pytest.approx(scan))
    assert plot_clearance(d, tmp_path / "clearance.png") is None
    assert_real_plot(tmp_path / "clearance.png", FIG_SIZE_IN, DPI)
    d.rec.messages.pop("/scan", None)
    assert "no clearance recorded" in plot_clearance(d, tmp_path / "none.png")


def test_the_summary_says_the_collisions_the_clearance_and_what_the_monitor_did(person):
    from beastbt.recording.report import obstacles_line, summary_text
    folder, summary = person
    text = summary_text(RunData.load(str(folder)))
    least = summary["truth"]["min_clearance_m"]
    assert f"  obstacles: 1 collision, least clearance {least:.2f} m (truth); collision monitor: " in text
    assert obstacles_line({"truth": {"collisions": 0, "min_clearance_m": 0.4},
                           "collision_monitor": {"episodes": {}}}) == \
        "  obstacles: 0 collisions, least clearance 0.40 m (truth); collision monitor: never acted"
    assert obstacles_line({"collision_monitor": {"episodes": {"stop": 2, "slow": 1}}}) == \
        "  obstacles: collision monitor: slow 1, stop 2"
    assert obstacles_line({}) is None
