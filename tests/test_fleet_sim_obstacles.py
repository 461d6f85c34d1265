"""Issue 22, item 5: simulated robots in one world meet each other.

Units: the other-robot obstacle (handed over from another thread, dropped when stale), seen by the LiDAR's ray
caster, met and counted by the contact world, placed by the simulator between ticks; the fleet's relay format.
End to end on loopback: a station and two ``beastbt serve --sim`` robots in one world, one standing in the other's
way: the moving one's LiDAR sees it and its collision monitor stops it short (``truth.collisions == 0``), where
without the other robot it drives on through that spot.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import time
import urllib.error
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from beastbt.fleet.shared_world import check_sim_field, others_of, poses_payload
from beastbt.robot.profile import load_profile
from beastbt.sim.contact import ContactWorld
from beastbt.sim.lidar_emulator import RayCaster, cast_circles
from beastbt.sim.obstacles import OtherRobot, OtherRobots
from beastbt.sim.robot import build_simulator
from beastbt.sim.world import empty_world


class FakeWall:
    """A monotonic clock the test moves (s)."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_other_robots_are_handed_over_in_name_order_and_dropped_once_stale():
    wall = FakeWall()
    others = OtherRobots(wall, max_age_s=1.0)
    assert others.take() == ()
    b, a = OtherRobot("b", 1.0, 0.0, 0.0, 0.2), OtherRobot("a", 0.0, 2.0, 0.0, 0.25)
    others.put([(b, 0.0), (a, 0.6)])
    assert [r.name for r in others.take()] == ["a", "b"]
    wall.now += 0.5  # a was heard 0.6 s before it came: now 1.1 s old, b 0.5 s
    assert [r.name for r in others.take()] == ["b"]
    moved = OtherRobot("b", 1.5, 0.0, 0.0, 0.2)
    others.put([(moved, 0.0)])
    assert others.take() == (moved,)  # the newest pose replaces the last
    wall.now += 1.01
    assert others.take() == ()  # a robot that went away is no longer an obstacle


def test_contact_meets_another_robot_counts_the_collision_and_forgets_it_when_it_goes():
    world = ContactWorld([], [], 0.2)
    assert world.empty and world.clearance(0.0, 0.0) == math.inf
    world.set_others([OtherRobot("b", 1.0, 0.0, 0.0, 0.3)])
    assert not world.empty
    assert world.clearance(0.0, 0.0) == pytest.approx(0.5)
    assert world.free_fraction(0.0, 0.0, 1.0, 0.0) == pytest.approx(0.5)  # stops at the touch, 0.5 m along
    assert world.free_fraction(0.5, 0.0, 0.0, 0.0) == 1.0  # backing away from it is free
    world.observe(0.0, 0.0)
    assert world.collisions == 0 and world.min_clearance_m == pytest.approx(0.5)
    world.observe(0.5, 0.0)
    assert world.collisions == 1 and world.in_contact
    # it drives off (its own simulator moved it): the bound follows it, the episode ends, nothing is left to touch
    world.set_others([OtherRobot("b", 3.0, 0.0, 0.0, 0.3)])
    world.observe(0.5, 0.0)
    assert not world.in_contact and world.clearance(0.5, 0.0) == pytest.approx(2.0)
    world.set_others([])
    assert world.empty and world.free_fraction(0.0, 0.0, 5.0, 0.0) == 1.0


def test_another_robot_that_comes_to_a_robot_standing_still_is_a_contact():
    world = ContactWorld([], [], 0.2)
    world.set_others([OtherRobot("b", 2.0, 0.0, 0.0, 0.2)])
    world.observe(0.0, 0.0)  # a look far away: the bound now says "1.6 m clear"
    world.set_others([OtherRobot("b", 0.3, 0.0, 0.0, 0.2)])  # it drove into us: the bound must not hide it
    world.observe(0.0, 0.0)
    assert world.collisions == 1


def test_the_lidar_ray_caster_sees_another_robot_as_a_circle_of_its_footprint():
    angles = np.radians([0.0, 5.0, 90.0, 180.0])
    hits = cast_circles(0.0, 0.0, angles, np.array([[2.0, 0.0]]), np.array([0.25]))
    assert hits[0] == pytest.approx(1.75)
    assert 1.75 < hits[1] < 2.25  # the slanted ray meets its rim farther away
    assert math.isinf(hits[2]) and math.isinf(hits[3])
    # nearer of two, behind a wall it is hidden
    hits = cast_circles(0.0, 0.0, angles[:1], np.array([[2.0, 0.0], [1.0, 0.0]]), np.array([0.25, 0.1]))
    assert hits[0] == pytest.approx(0.9)


def test_the_simulator_places_the_others_between_ticks_and_its_lidar_sees_them():
    profile = load_profile("sim")
    sim = build_simulator(profile, empty_world(), 0, shared=True)
    assert sim.drive.contact is not None
    from beastbt.sim.lidar_emulator import make_emulator
    lidar = make_emulator("ld19", RayCaster([], []), sim.truth, sim.drive.contact, (0.0, 0.0, 0.0),
                          np.random.default_rng(0))
    deg, mm = lidar.measure(0, 450)  # a whole turn: nothing in an empty world
    assert not mm.any()
    handed = OtherRobots(FakeWall())
    handed.put([(OtherRobot("b", 1.5, 0.0, 0.0, 0.25), 0.0)])
    sim.others = handed.take
    sim.advance(0.05)
    deg, mm = lidar.measure(0, 450)
    ahead = mm[(deg < 3.0) | (deg > 357.0)]  # straight ahead (the device counts clockwise)
    assert ahead.size and np.all(np.abs(ahead - 1250.0) < 60.0)
    assert not mm[(deg > 30.0) & (deg < 330.0)].any()  # only there
    # drive into it: the footprint stops at the touch, and the truth counts one collision
    sim.drive.set_body_targets(0.5, 0.0)
    sim.advance(6.0)
    radius = sim.drive.model.footprint_radius_m
    assert sim.truth.x == pytest.approx(1.5 - 0.25 - radius, abs=1e-3)
    assert sim.drive.contact.collisions == 1


def test_the_relay_takes_the_others_of_the_same_world_only():
    sim = {"world": "campus", "x": 1.0, "y": 2.0, "yaw": 0.5, "radius_m": 0.2}
    raw = poses_payload([("me", sim, 0.1), ("b", sim, 0.2), ("c", {**sim, "world": "office"}, 0.0),
                         ("old", sim, 1.5)]).encode()
    got = others_of(raw, "me", "campus")
    assert [(r.name, r.x, r.y, r.radius_m, age) for r, age in got] == [("b", 1.0, 2.0, 0.2, 0.2)]
    assert others_of(raw, "me", None) == []  # not simulated: nobody to meet
    assert others_of(b"not json", "me", "campus") == []
    bad = json.dumps({"robots": [{"name": "x/y", **sim}, {"name": "z", **sim, "radius_m": -1},
                                 {"name": "n", **sim, "x": "nan"}, "junk"]}).encode()
    assert others_of(bad, "me", "campus") == []
    assert check_sim_field({**sim, "radius_m": 1e9}) is None and check_sim_field(sim) == sim


def test_the_station_relays_only_simulated_robots_heard_within_a_second():
    from beastbt.fleet.station import FleetTable
    wall = FakeWall()
    table = FleetTable(wall)
    sim = {"world": "campus", "x": 1.0, "y": 2.0, "yaw": 0.5, "radius_m": 0.2}
    table.state("b", {"status": "idle", "sim": sim})
    table.state("real", {"status": "idle"})  # a real robot has no 'sim': never relayed
    table.state("broken", {"status": "idle", "sim": {**sim, "radius_m": "big"}})
    wall.now += 0.4
    table.state("a", {"status": "running", "sim": {**sim, "x": 3.0}})
    assert [(n, s["x"], round(age, 3)) for n, s, age in table.sim_poses()] == [("a", 3.0, 0.0), ("b", 1.0, 0.4)]
    wall.now += 0.7  # b was last heard 1.1 s ago
    assert [n for n, _, _ in table.sim_poses()] == ["a"]


def test_the_agent_puts_its_true_pose_in_its_state_and_hands_the_others_of_its_world_to_its_simulator():
    from beastbt.fleet.agent import FleetAgent
    from beastbt.fleet.config import FleetOptions
    wall = FakeWall()
    agent = FleetAgent("me", FleetOptions(endpoint="tcp/127.0.0.1:7447"), wall=wall)
    assert "sim" not in agent.current_state()  # not simulated (or not in a shared world): no truth on the fleet
    world = empty_world()
    sim = build_simulator(load_profile("sim"), world, 0, shared=True)
    sim.truth.x, sim.truth.y = 1.25, -0.5
    agent.attach_sim(sim)
    assert agent.current_state()["sim"] == {"world": world.name, "x": 1.25, "y": -0.5, "yaw": 0.0,
                                            "radius_m": sim.drive.model.footprint_radius_m}

    class Sample:
        def __init__(self, raw: bytes) -> None:
            self.payload = type("P", (), {"to_bytes": lambda _self: raw})()
    near = {"world": world.name, "x": 2.0, "y": -0.5, "yaw": 0.0, "radius_m": 0.2}
    agent._on_sim_poses(Sample(poses_payload([("me", near, 0.0), ("b", near, 0.1)]).encode()))
    sim.advance(0.02)
    assert [o.name for o in sim.drive.contact.others] == ["b"]
    wall.now += 1.0  # no relay since: b is dropped at the next tick
    sim.advance(0.04)
    assert sim.drive.contact.others == ()
    sim.truth.x = 4.0
    agent.detach_sim()  # the run ended: it stands where it stopped, its simulator no longer asks
    assert agent.current_state()["sim"]["x"] == 4.0 and sim.others is None


# -- end to end: a station and two serve --sim robots --------------------------------------------------------------

def world_at(folder: Path, name: str, x: float, yaw_deg: float = 0.0) -> Path:
    """An empty world ``shared`` (the same for both robots) with its start at (x, 0) facing ``yaw_deg``."""
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump({"world": "shared", "start": {"x": x, "y": 0.0, "yaw_deg": yaw_deg}}))
    return path


def stop(procs: dict) -> None:
    for proc in procs.values():
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    for proc in procs.values():
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()


def listed(base: str, names: set) -> bool:
    from tests.test_fleet_done import robots
    try:
        return names <= {n for n, r in robots(base).items() if r["alive"]}
    except (urllib.error.URLError, ConnectionError):
        return False  # the station is still starting


def summary_of(runs: Path) -> dict:
    found = sorted(runs.glob("*/summary.json"))
    assert len(found) == 1, found
    return json.loads(found[0].read_text())


@pytest.mark.parametrize("other", [True, False], ids=["other-in-the-way", "nobody-in-the-way"])
def test_a_robot_standing_in_the_way_is_seen_and_the_moving_one_stops_short(tmp_path, other):
    pytest.importorskip("zenoh")
    from fleet_support import free_port, http, wait_for
    from tests.test_fleet_done import beastbt, robots
    zport, hport = free_port(), free_port()
    endpoint, base = f"tcp/127.0.0.1:{zport}", f"http://127.0.0.1:{hport}"
    runs = tmp_path / "runs-mover"
    procs = {"station": beastbt("station", "--insecure-loopback", "--listen", endpoint, "--console", f"127.0.0.1:{hport}",
                                cwd=str(tmp_path)),
             "mover": beastbt("serve", "--sim", "--insecure-loopback", "--name", "mover", "--fleet", endpoint, "--speed", "4",
                              "--world", str(world_at(tmp_path, "mover", 0.0)), "--runs-dir", str(runs),
                              cwd=str(tmp_path))}
    if other:
        procs["stander"] = beastbt("serve", "--sim", "--insecure-loopback", "--name", "stander", "--fleet", endpoint, "--world",
                                   str(world_at(tmp_path, "stander", 2.0)), "--no-record", cwd=str(tmp_path))
    try:
        wait_for(lambda: listed(base, set(procs) - {"station"}), 12.0, "the robots listed")
        if other:
            time.sleep(0.6)  # a few relays of the stander's pose reach the mover
        mission = "mission: through\nsteps:\n  - drive: {distance: 3 m, speed: 0.3 m/s, stuck_after: 3 s}\n"
        status, answer = http("POST", f"{base}/api/robots/mover/mission", mission.encode(), "application/yaml")
        assert status == 200, answer
        wait_for(lambda: (robots(base)["mover"]["last_run"] or {}).get("status"), 15.0, "the mover's run ends")
        summary = summary_of(runs)
    finally:
        stop(procs)
    truth: Any = summary["truth"]
    x = truth["final_pose"]["x"]
    seen = [e for e in summary["events"] if e["kind"] == "collision_monitor" and "zone" in e["text"]]
    if other:
        # the stander (its footprint at 2 m) was seen: stopped short of it, never touched it
        assert truth["collisions"] == 0, summary["events"][-5:]
        assert 0.8 < x < 2.0 - 0.35, x
        assert seen, summary["events"]  # the LiDAR's points of it in the monitor's zones
        assert truth["min_clearance_m"] is not None and truth["min_clearance_m"] > 0.0
    else:
        assert x > 2.6 and not seen  # the same mission alone drives on through where the stander stood


def test_two_robots_driving_at_each_other_both_stop_without_touching(tmp_path):
    pytest.importorskip("zenoh")
    from fleet_support import free_port, http, wait_for
    from tests.test_fleet_done import beastbt, robots
    zport, hport = free_port(), free_port()
    endpoint, base = f"tcp/127.0.0.1:{zport}", f"http://127.0.0.1:{hport}"
    procs = {"station": beastbt("station", "--insecure-loopback", "--listen", endpoint, "--console", f"127.0.0.1:{hport}",
                                cwd=str(tmp_path))}
    for name, x, yaw in (("west", 0.0, 0.0), ("east", 2.4, 180.0)):  # facing each other, 2.4 m apart
        procs[name] = beastbt("serve", "--sim", "--insecure-loopback", "--name", name, "--fleet", endpoint, "--world",
                              str(world_at(tmp_path, name, x, yaw)), "--runs-dir", str(tmp_path / f"runs-{name}"),
                              cwd=str(tmp_path))
    try:
        wait_for(lambda: listed(base, {"west", "east"}), 12.0, "both robots listed")
        time.sleep(0.6)  # each has the other's pose
        mission = "mission: head_on\nsteps:\n  - drive: {distance: 3 m, speed: 0.2 m/s, stuck_after: 2 s}\n"
        for name in ("west", "east"):  # at real time: each sees the other at most about 0.35 s late
            status, answer = http("POST", f"{base}/api/robots/{name}/mission", mission.encode(), "application/yaml")
            assert status == 200, answer
        for name in ("west", "east"):
            wait_for(lambda: (robots(base)[name]["last_run"] or {}).get("status"), 20.0, f"{name}'s run ends")
        west, east = (summary_of(tmp_path / f"runs-{n}")["truth"] for n in ("west", "east"))
    finally:
        stop(procs)
    assert west["collisions"] == 0 and east["collisions"] == 0, (west, east)
    gap = east["final_pose"]["x"] - west["final_pose"]["x"]
    assert west["final_pose"]["x"] > 0.2 and east["final_pose"]["x"] < 2.2  # both drove towards the other
    assert 0.3 < gap < 1.4, gap  # and both stopped short of the other's footprint (0.15 m each)


def test_on_tls_the_station_relays_the_poses_to_a_robot_and_another_robots_put_does_not_reach_it(tmp_path_factory):
    zenoh = pytest.importorskip("zenoh")
    from tests.test_fleet_tls import tls_fleet, wait_for
    fleet = tls_fleet.__wrapped__(tmp_path_factory)  # the TLS fleet of test_fleet_tls: station, robot 'tls-1'
    setup = next(fleet)
    try:
        station, agent, keys_dir = setup["station"], setup["agent"], setup["keys"]
        sim = {"world": "shared", "x": 1.0, "y": 0.0, "yaw": 0.0, "radius_m": 0.2}
        agent.stand(sim)  # tls-1 is a simulated robot of 'shared'
        heard: list = []
        take = agent.others.put
        agent.others.put = lambda robots: (heard.extend(r.name for r, _ in robots), take(robots))
        # the station's relay of two simulated robots reaches it, on TLS
        station.table.state("b", {"sim": {**sim, "x": 2.0}})
        station.table.state("c", {"sim": {**sim, "x": 3.0}})
        wait_for(lambda: [r.name for r in agent.others.take()] == ["b", "c"], 2.0, "the relay reaches tls-1")
        # another robot (the robots' certificate), once it hears the relay too, tries to plant a robot in tls-1's
        # world: its put does not reach tls-1 (robots do not hear each other, and the access control lets a robot
        # put only its state and events)
        robot = json.loads((keys_dir / "robot.json5").read_text())
        robot["connect"]["endpoints"] = [setup["endpoint"]]
        session = zenoh.open(zenoh.Config.from_json5(json.dumps(robot)))
        try:
            relays: list = []
            sub = session.declare_subscriber("beastbt/fleet/sim/poses", lambda sample: relays.append(sample))
            station.table.state("b", {"sim": {**sim, "x": 2.0}})
            wait_for(lambda: relays, 2.0, "the other robot hears the relay")
            for _ in range(5):
                session.put("beastbt/fleet/sim/poses", poses_payload([("ghost", sim, 0.0)]))
                time.sleep(0.1)
            sub.undeclare()
            assert "b" in heard and "ghost" not in heard
        finally:
            session.close()
    finally:
        next(fleet, None)
