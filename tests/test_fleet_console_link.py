"""The station links a robot's console only when it is ``http(s)://`` on the robot's own address (issue 38, 6): the
address its Zenoh session comes from; anything else is dropped, with the reason in ``GET /api/robots``.
"""

from __future__ import annotations

import pytest

from fleet_support import free_port, wait_for  # noqa: E402

from beastbt.fleet.console_link import robot_console_url  # noqa: E402
from beastbt.fleet.station import FleetTable  # noqa: E402


@pytest.mark.parametrize("url, address, linked", [
    ("http://127.0.0.1:8095/", "127.0.0.1", "http://127.0.0.1:8095/"),
    ("https://10.0.0.5:8443/console?token=secret#x", "10.0.0.5", "https://10.0.0.5:8443/console"),
    ("http://beast-01:8080/", "10.0.0.5", "http://10.0.0.5:8080/"),  # a console on 0.0.0.0 names its computer
    ("http://localhost:8080/", "127.0.0.1", "http://127.0.0.1:8080/"),
    ("http://[::1]:8080/", "::1", "http://[::1]:8080/"),
    ("http://[::ffff:10.0.0.5]:8080/", "10.0.0.5", "http://10.0.0.5:8080/"),
])
def test_a_console_on_the_robots_own_address_is_linked(url, address, linked):
    assert robot_console_url(url, address) == (linked, None)


@pytest.mark.parametrize("url, address, reason", [
    ("javascript:alert(document.cookie)", "10.0.0.5", "not http:// or https://"),
    ("data:text/html,<script>x</script>", "10.0.0.5", "not http:// or https://"),
    ("file:///etc/passwd", "10.0.0.5", "not http:// or https://"),
    ("http://10.0.0.9:8080/", "10.0.0.5", "not on the robot's own address 10.0.0.5"),
    ("http://127.0.0.1:8090/", "10.0.0.5", "loopback"),  # the station's own page, on the viewer's computer
    ("http://user:pw@10.0.0.5/", "10.0.0.5", "names a user"),
    ("http://10.0.0.5:99999/", "10.0.0.5", "not a URL"),
    ("http://10.0.0.5:8080/", None, "does not know the robot's address"),
    (["http://10.0.0.5/"], "10.0.0.5", "not a URL"),
    ("http://" + "a" * 3000, "10.0.0.5", "not a URL"),
])
def test_anything_else_is_dropped_with_the_reason(url, address, reason):
    linked, problem = robot_console_url(url, address)
    assert linked is None and reason in problem


def test_the_table_checks_each_robots_console_against_its_sessions_address():
    table = FleetTable(addresses=lambda: {"aa11": "10.0.0.5", "bb22": "10.0.0.6"})
    table.alive("honest", True)
    table.state("honest", {"status": "running", "zid": "aa11", "console_url": "http://beast-01:8080/"})
    table.alive("rogue", True)
    table.state("rogue", {"status": "running", "zid": "bb22", "console_url": "https://phish.example:443/login"})
    table.alive("liar", True)
    table.state("liar", {"status": "running", "zid": "bb22", "console_url": "http://10.0.0.5:8080/"})
    table.alive("plain", True)
    table.state("plain", {"status": "idle", "zid": "cc33"})
    robots = {r["name"]: r for r in table.robots()}
    assert robots["honest"]["console_url"] == "http://10.0.0.5:8080/" and robots["honest"]["console_url_problem"] is None
    # a name is never asked of DNS: the link goes to the robot's own address, whatever name it gave
    assert robots["rogue"]["console_url"] == "https://10.0.0.6:443/login"
    assert robots["liar"]["console_url"] is None and "10.0.0.6" in robots["liar"]["console_url_problem"]
    assert robots["plain"]["console_url"] is None and robots["plain"]["console_url_problem"] is None


def test_a_live_station_finds_each_robots_address_from_its_zenoh_link():
    pytest.importorskip("zenoh")
    from beastbt.fleet.agent import FleetAgent
    from beastbt.fleet.config import FleetOptions
    from beastbt.fleet.station import Station
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    station = Station(endpoint).open()
    agents = {name: FleetAgent(name, FleetOptions(endpoint)) for name in ("near", "far")}
    urls = {"near": "http://127.0.0.1:8123/", "far": "http://192.0.2.7:8123/"}
    for name, agent in agents.items():  # the console_url a run's console would put in the state
        state = agent.current_state
        agent.current_state = lambda state=state, url=urls[name]: {**state(), "console_url": url}
        agent.start()
    try:
        wait_for(lambda: {r["name"] for r in station.table.robots() if r["alive"]} == {"near", "far"}, 20.0,
                 "both robots listed")
        robots = {r["name"]: r for r in station.table.robots()}
        assert agents["near"].zid and station.table._robots["near"].state["zid"] == agents["near"].zid
        assert robots["near"]["console_url"] == "http://127.0.0.1:8123/"
        assert robots["far"]["console_url"] is None
        assert "not on the robot's own address 127.0.0.1" in robots["far"]["console_url_problem"]
    finally:
        for agent in agents.values():
            agent.close()
        station.close()
