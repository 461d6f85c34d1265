"""The station's table and HTTP API against robots' agents in this process (no run), and the key space's checks.

What the station answers for an idle robot, a missing one and a robot that leaves; the e-stop
that is never refused (idle, any content type, the fleet-wide put); and the console's guard
applied to the station (Host, JSON-only controls, a mission as YAML).
"""

from __future__ import annotations

import io
import time
import zipfile

import pytest

from fleet_support import free_port, http, wait_for  # noqa: E402

pytest.importorskip("zenoh")

from beastbt.commands.serve import unpack  # noqa: E402
from beastbt.fleet import keys  # noqa: E402
from beastbt.fleet.agent import FleetAgent  # noqa: E402
from beastbt.fleet.config import FleetOptions, parse_endpoint  # noqa: E402
from beastbt.fleet.station import Station, StationServer  # noqa: E402


@pytest.fixture(scope="module")
def station():
    """A station (router and HTTP API) and two idle agents: ``serving`` takes missions, ``running`` does not."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    st = Station(endpoint).open()
    server = StationServer(st, "127.0.0.1", 0).start()
    agents = {"serving": FleetAgent("serving", FleetOptions(endpoint), takes_missions=True).start(),
              "running": FleetAgent("running", FleetOptions(endpoint)).start()}
    base = f"http://127.0.0.1:{server.port}"
    wait_for(lambda: {"serving", "running"} <= {r["name"] for r in st.table.robots() if r["alive"]}, 5.0,
             "both agents listed")
    yield {"base": base, "agents": agents, "station": st, "endpoint": endpoint}
    for agent in agents.values():
        agent.close()
    server.close()
    st.close()


def test_an_idle_robot_is_listed_with_the_contract_fields(station):
    status, body = http("GET", f"{station['base']}/api/robots")
    assert status == 200
    robot = {r["name"]: r for r in body["robots"]}["serving"]
    assert {"name", "status", "alive", "pose", "battery", "step", "progress", "last_seen_s"} <= set(robot)
    assert robot["status"] == "idle" and robot["alive"] is True and 0 <= robot["last_seen_s"] < 1.0


def test_controls_without_a_mission_are_refused_with_the_reason_but_the_estop_never(station):
    base = station["base"]
    status, body = http("POST", f"{base}/api/robots/serving/pause", b"{}")
    assert status == 409 and "no mission is running on serving" in body["error"]
    status, body = http("POST", f"{base}/api/robots/serving/estop", b"")
    assert status == 200 and body["estop"] is True and body["running"] is False
    assert station["agents"]["serving"].estop_latched
    status, body = http("POST", f"{base}/api/robots/serving/mission", b"mission: m\nsteps: [stop]\n",
                        content_type="application/yaml")
    assert status == 409 and "e-stop" in body["error"]
    status, body = http("POST", f"{base}/api/robots/serving/estop_reset", b"{}")
    assert status == 200 and body["estop"] is False
    status, body = http("POST", f"{base}/api/robots/serving/estop_reset", b"{}")
    assert status == 409 and "not latched" in body["error"]


def test_estop_all_is_a_put_every_robot_hears_whatever_the_content_type(station):
    agents = station["agents"]
    status, body = http("POST", f"{station['base']}/api/estop-all", b"stop!", content_type="text/plain")
    assert status == 200 and {"serving", "running"} <= set(body["robots"])
    wait_for(lambda: all(a.estop_latched for a in agents.values()), 2.0, "every agent latched")
    for name in agents:
        assert http("POST", f"{station['base']}/api/robots/{name}/estop_reset", b"{}")[0] == 200


def test_a_run_that_is_not_served_takes_no_mission(station):
    status, body = http("POST", f"{station['base']}/api/robots/running/mission", b"mission: m\nsteps: [stop]\n",
                        content_type="application/yaml")
    assert status == 409 and "beastbt serve" in body["error"]


def test_unknown_robots_controls_and_bad_names_are_4xx(station):
    base = station["base"]
    assert http("POST", f"{base}/api/robots/nobody/pause", b"{}")[0] == 404
    status, body = http("POST", f"{base}/api/robots/serving/jump", b"{}")
    assert status == 404 and "pause" in body["error"]
    status, body = http("POST", f"{base}/api/robots/fleet/pause", b"{}")
    assert status == 400 and "taken" in body["error"]
    status, body = http("POST", f"{base}/api/robots/serving/teleop", b'{"linear": NaN}')
    assert status == 400


def test_the_consoles_guard_applies(station):
    base = station["base"]
    status, body = http("GET", f"{base}/api/robots", headers={"Host": "evil.example"})
    assert status == 403 and "DNS rebinding" in body["error"]
    status, body = http("POST", f"{base}/api/robots/serving/pause", b"{}", content_type="text/plain")
    assert status == 403 and "application/json" in body["error"]
    status, body = http("POST", f"{base}/api/robots/serving/mission", b"mission: m", content_type="text/plain")
    assert status == 403
    status, body = http("POST", f"{base}/api/robots/serving/pause", b"{}",
                        headers={"Content-Type": "application/json", "Origin": "http://evil.example"})
    assert status == 403


def test_a_robot_that_leaves_shows_lost_at_once(station):
    endpoint = station["endpoint"]
    agent = FleetAgent("leaving", FleetOptions(endpoint)).start()
    table = station["station"].table
    wait_for(lambda: any(r["name"] == "leaving" and r["alive"] for r in table.robots()), 5.0, "listed")
    agent.close()
    gone = time.monotonic()
    wait_for(lambda: any(r["name"] == "leaving" and r["status"] == "lost" for r in table.robots()), 2.0, "lost")
    assert time.monotonic() - gone < 2.0


def test_names_and_keys():
    assert keys.cmd_key("beast-01", "pause") == "beastbt/beast-01/cmd/pause"
    assert keys.robot_of("beastbt/beast-01/state") == "beast-01"
    assert keys.robot_of("beastbt/fleet/estop") is None
    for bad in ("", "a/b", "*", "**", "a b", "$*", "fleet", "x" * 65):
        assert keys.name_problem(bad) is not None, bad
    with pytest.raises(ValueError, match="unknown control"):
        keys.cmd_key("a", "selfdestruct")
    assert parse_endpoint("7447") == "tcp/127.0.0.1:7447"
    assert parse_endpoint("[::1]:7447") == "tcp/[::1]:7447"
    with pytest.raises(ValueError, match="Zenoh endpoint"):
        parse_endpoint("http://x:1")


def test_a_mission_zip_is_unpacked_inside_its_folder_only(tmp_path):
    def zipped(files: dict) -> bytes:
        out = io.BytesIO()
        with zipfile.ZipFile(out, "w") as z:
            for name, text in files.items():
                z.writestr(name, text)
        return out.getvalue()
    path = unpack(zipped({"mission.yaml": "mission: m\n", "routes/r.gpx": "<gpx/>"}), tmp_path / "a")
    assert path == tmp_path / "a" / "mission.yaml" and (tmp_path / "a" / "routes" / "r.gpx").exists()
    with pytest.raises(ValueError, match="outside"):
        unpack(zipped({"../evil.yaml": "x"}), tmp_path / "b")
    with pytest.raises(ValueError, match="mission.yaml"):
        unpack(zipped({"a.yaml": "x", "b.yaml": "y"}), tmp_path / "c")


def test_simulated_robots_start_side_by_side_in_the_shared_world(tmp_path):
    from beastbt.fleet.simulate import SPACING_M, world_for
    from beastbt.sim.world import load_world
    from conftest import REPO
    starts = [load_world(str(world_for(i, str(REPO / "worlds" / "campus.yaml"), tmp_path))) for i in range(3)]
    assert {w.name for w in starts} == {"campus"} and len({(w.start_x, w.start_y) for w in starts}) == 3
    for a, b in zip(starts, starts[1:]):
        assert abs(((b.start_x - a.start_x) ** 2 + (b.start_y - a.start_y) ** 2) ** 0.5 - SPACING_M) < 1e-3
        assert b.start_yaw == a.start_yaw


def test_a_bad_fleet_config_is_said_with_its_position_before_anything_moves(tmp_path):
    from beastbt.core.errors import InvalidInput
    bad = tmp_path / "robot.json5"
    bad.write_text('{mode: "peer",\n connect: {endpoints: [12]}}\n')
    with pytest.raises(InvalidInput) as caught:
        FleetAgent("x", FleetOptions("tcp/127.0.0.1:7447", str(bad)))
    text = caught.value.format()
    assert text.startswith(f"{bad}:2:") and "not a Zenoh configuration" in text and "/root/.cargo" not in text
    with pytest.raises(InvalidInput, match="no Zenoh configuration file"):
        FleetAgent("x", FleetOptions(None, str(tmp_path / "missing.json5")))
