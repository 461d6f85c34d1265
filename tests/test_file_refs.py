"""Every file a mission, a world or a request names is confined and bounded (issue 38, point 1; issue 37, item 4).

The policy itself (beastbt/core/file_refs.py), then the probe's inputs as a user sends them: on the command
line (allowed anywhere, but regular files only and never quoted), and to a studio in its own process under a
memory limit (so that a regression fails fast instead of eating the machine): ``/etc/passwd``, ``/dev/zero``,
``/tmp/x.yaml/.``, a FIFO, ``..`` climbs, absolute paths and links out of the folder, through the robot field and
the ``world:`` and ``map:`` of a text, on /api/validate, /api/tree and /api/map.
"""

from __future__ import annotations

import http.client
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from beastbt.core.file_refs import CLI, JOYSTICK, MAP, ROBOT, ROUTE, WORLD, FileKind, FileRefs, RefusedFile, \
    read_capped
from conftest import REPO
from fleet_support import free_port, wait_for

MEMORY_LIMIT = 1 << 30
"""Address space of a probed child process (bytes): a studio or a validate takes a quarter of it."""
SECRET = "root:"
"""What /etc/passwd starts with: no answer may show it."""
MISSION = "mission: m\n{line}\nsteps:\n  - stop\n"


def limited() -> None:
    """In the child: at most :data:`MEMORY_LIMIT` of address space."""
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def test_a_regular_file_is_read_within_its_cap_and_a_device_a_pipe_or_a_folder_never(tmp_path):
    small = tmp_path / "w.yaml"
    small.write_text("world: w\n")
    assert read_capped(small, WORLD) == b"world: w\n"
    big = tmp_path / "big.gpx"
    big.write_bytes(b"x" * 2048)
    with pytest.raises(RefusedFile, match=r"'big.gpx' is 2 kB: a route file is read up to 1,000 bytes|'big.gpx' is 2 kB: a route file is read up to 1 kB"):
        read_capped(big, FileKind("route file", 1000), "big.gpx")
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    started = time.monotonic()
    for path, says in (("/dev/zero", "not a regular file"), (str(fifo), "not a regular file"),
                       (str(tmp_path) + "/.", "folder, not a file"), (str(tmp_path), "folder, not a file")):
        with pytest.raises(RefusedFile, match=says):
            read_capped(path, JOYSTICK)
        with pytest.raises(RefusedFile, match=says):
            CLI.check(path, WORLD)
    assert time.monotonic() - started < 5.0  # a FIFO with no writer does not block the open


def test_confined_paths_stay_inside_the_folder_and_refusals_name_the_path_as_written(tmp_path):
    root = tmp_path / "folder"
    (root / "missions").mkdir(parents=True)
    (root / "worlds").mkdir()
    (root / "worlds" / "mine.yaml").write_text("world: mine\n")
    outside = tmp_path / "outside.yaml"
    outside.write_text("world: secret\n")
    (root / "missions" / "out.yaml").symlink_to(outside)
    (root / "missions" / "in.yaml").symlink_to(root / "worlds" / "mine.yaml")
    refs = FileRefs.inside(root, "the studio's folder")
    base = root / "missions"
    assert refs.locate("../worlds/mine.yaml", base, WORLD) == (root / "worlds" / "mine.yaml").resolve()
    assert refs.locate("in.yaml", base, WORLD) == (root / "worlds" / "mine.yaml").resolve()
    for written, says in (("/etc/passwd", "is an absolute path"), (str(outside), "is an absolute path"),
                          ("../../outside.yaml", "climbs out of the studio's folder"),
                          ("out.yaml", "is a link that leads out of the studio's folder"),
                          ("/dev/zero", "is an absolute path"), ("/tmp/x.yaml/.", "names a folder, not a file")):
        with pytest.raises(RefusedFile) as refused:
            refs.locate(written, base, WORLD)
        assert f"the world file '{written}' {says}" in refused.value.message
        assert "secret" not in refused.value.message + refused.value.hint
    # the command line reads where the user points, but a device is still no file
    assert CLI.locate(str(outside), base, WORLD) == outside
    with pytest.raises(RefusedFile, match="not a regular file"):
        CLI.locate("/dev/zero", base, WORLD)


def test_a_bare_name_is_looked_up_beside_the_file_then_among_the_shipped_ones(tmp_path):
    assert CLI.locate("campus", tmp_path, WORLD).read_text() == (REPO / "worlds" / "campus.yaml").read_text()
    assert CLI.locate("office", tmp_path, MAP).name == "office.yaml"
    assert CLI.locate("sim", tmp_path, ROBOT).name == "sim.yaml"
    (tmp_path / "campus.yaml").write_text("world: my_campus\n")
    assert CLI.locate("campus", tmp_path, WORLD) == tmp_path / "campus.yaml"  # the folder's own comes first
    (tmp_path / "sub").mkdir()
    confined = FileRefs.inside(tmp_path / "sub", "the folder")
    assert confined.locate("corridor", tmp_path / "sub", WORLD).name == "corridor.yaml"  # shipped: allowed
    with pytest.raises(RefusedFile, match=r"no world file called 'campos'.*did you mean 'campus'"):
        CLI.locate("campos", tmp_path / "sub", WORLD)
    with pytest.raises(RefusedFile, match="the route file .route. does not exist"):  # no shipped ones: a path
        CLI.locate("route", tmp_path, ROUTE)


def test_world_campus_validates_from_any_folder(tmp_path):
    from beastbt.mission.model import load_mission
    from beastbt.validate import validate_file
    mission = tmp_path / "far" / "away.yaml"
    mission.parent.mkdir()
    mission.write_text("mission: m\nworld: campus\nmap: office\nplaces:\n  a: {x: 1 m, y: 1 m}\n"
                       "steps:\n  - go_to: a\n")
    assert validate_file(str(mission)) == []
    loaded = load_mission(mission)
    assert loaded.world.name == "campus.yaml" and loaded.map_grid is not None


def run_cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """``python -m beastbt ARGS`` under the memory limit (60 s at most)."""
    return subprocess.run([sys.executable, "-m", "beastbt", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=60, preexec_fn=limited, env={**os.environ, "PYTHONPATH": str(REPO)})


def test_the_command_line_reads_any_regular_file_but_never_a_device_and_never_quotes_one(tmp_path):
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    folder = tmp_path / "x.yaml"
    folder.mkdir()
    cases = {"zero.yaml": ("world: /dev/zero", "2:8: error: the world file '/dev/zero' is not a regular file"),
             "fifo.yaml.m": (f"world: {fifo}", f"2:8: error: the world file '{fifo}' is not a regular file"),
             "dot.yaml": (f"world: {folder}/.", f"2:8: error: the world file '{folder}/.' names a folder, not a file"),
             "map.yaml": ("map: /dev/zero", "2:6: error: the map file '/dev/zero' is not a regular file"),
             "passwd.yaml": ("world: /etc/passwd", "2:8: error: the world file /etc/passwd has problems")}
    for name, (line, _) in cases.items():
        (tmp_path / name).write_text(MISSION.format(line=line))
    started = time.monotonic()
    done = run_cli("validate", *cases, cwd=tmp_path)
    assert time.monotonic() - started < 30.0
    assert done.returncode == 2, done.stderr
    for name, (_, says) in cases.items():
        assert f"{name}:{says}" in done.stderr, done.stderr
    assert SECRET not in done.stderr + done.stdout and "Traceback" not in done.stderr
    # a joystick script and a mission named on the command line: the same rules
    done = run_cli("validate", "/dev/zero", str(fifo), cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.count("is not a regular file") == 2, done.stderr
    done = run_cli("run", str(tmp_path / "zero.yaml"), "--no-record", "--joystick", "/dev/zero", cwd=tmp_path)
    assert done.returncode == 2 and "not a regular file" in done.stderr, done.stderr


def test_run_files_inside_confines_what_a_try_reads(tmp_path):
    mission = tmp_path / "m.yaml"
    mission.write_text(MISSION.format(line="world: ../outside.yaml"))
    (tmp_path.parent / "outside.yaml").write_text("world: outside\n")
    done = run_cli("run", str(mission), "--no-record", "--files-inside", str(tmp_path), cwd=tmp_path)
    assert done.returncode == 2
    assert "m.yaml:2:8: error: the world file '../outside.yaml' climbs out of the folder" in done.stderr, done.stderr


# -- the studio, in its own process under the memory limit ----------------------------------------------------

class StudioProcess:
    """``beastbt studio FOLDER`` on a free loopback port, under :data:`MEMORY_LIMIT`."""

    def __init__(self, folder: Path) -> None:
        self.port = free_port()
        self.process = subprocess.Popen([sys.executable, "-m", "beastbt", "studio", str(folder), "--listen",
                                         f"127.0.0.1:{self.port}"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                        text=True, preexec_fn=limited, env={**os.environ, "PYTHONPATH": str(REPO)})
        wait_for(self.up, 30.0, "the studio answers", period_s=0.1)

    def up(self) -> bool:
        try:
            return self.post("/api/validate", {"text": "mission: m\nsteps: [stop]\n"})[0] == 200
        except OSError:
            return False

    def post(self, path: str, body: dict, timeout_s: float = 30.0) -> tuple[int, str]:
        """(status, raw answer text) of a JSON POST."""
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=timeout_s)
        conn.request("POST", path, json.dumps(body), {"Content-Type": "application/json",
                                                     "Host": f"127.0.0.1:{self.port}"})
        response = conn.getresponse()
        answer = response.status, response.read().decode("utf-8", "replace")
        conn.close()
        return answer

    def get(self, path: str) -> tuple[int, str]:
        """(status, raw answer text) of a GET."""
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=30)
        conn.request("GET", path, headers={"Host": f"127.0.0.1:{self.port}"})
        response = conn.getresponse()
        answer = response.status, response.read().decode("utf-8", "replace")
        conn.close()
        return answer

    def peak_rss_bytes(self) -> int:
        """The studio's peak resident memory so far (VmHWM)."""
        for line in Path(f"/proc/{self.process.pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
        raise AssertionError("no VmHWM")

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(5)


@pytest.fixture(scope="module")
def studio(tmp_path_factory):
    root = tmp_path_factory.mktemp("confined")
    folder = root / "studio"
    shutil.copytree(REPO / "missions", folder / "missions")
    shutil.copytree(REPO / "worlds", folder / "worlds", ignore=shutil.ignore_patterns("__init__.py", "__pycache__"))
    (folder / "missions" / "passwd.yaml").symlink_to("/etc/passwd")
    (folder / "missions" / "zero.yaml").symlink_to("/dev/zero")
    (folder / "missions" / "x.yaml").mkdir()
    os.mkfifo(folder / "missions" / "fifo.yaml")
    (root / "outside.yaml").write_text("world: hidden_content\n")
    s = StudioProcess(folder)
    yield s
    s.close()


PROBES = ("/etc/passwd", "/dev/zero", "/tmp/x.yaml/.", "../../outside.yaml", "../../../../../../etc/passwd",
          "passwd.yaml", "zero.yaml", "x.yaml/.", "fifo.yaml")
"""What the probe named: absolute paths, devices, a folder with a dot, climbs, links out, a FIFO inside."""


def test_the_robot_field_reads_nothing_outside_the_folder_nor_any_device(studio):
    for robot in PROBES:
        for endpoint in ("/api/validate", "/api/tree", "/api/map"):
            started = time.monotonic()
            status, text = studio.post(endpoint, {"text": MISSION.format(line="rate: 10 Hz"),
                                                  "path": "missions/m.yaml", "robot": robot})
            took = time.monotonic() - started
            assert took < 5.0, (robot, endpoint, took)
            assert SECRET not in text and "hidden_content" not in text and "internal error" not in text, text
            if endpoint == "/api/map":
                continue  # the map is drawn without a robot
            assert status in (400, 403, 404), (robot, endpoint, status, text)
            assert f"'{robot}'" in json.loads(text)["error"], text
    assert studio.process.poll() is None and studio.peak_rss_bytes() < 200e6


def test_world_and_map_of_a_text_are_read_only_inside_the_folder(studio):
    for key in ("world", "map"):
        for written in PROBES:
            text = MISSION.format(line=f"{key}: {written}")
            for endpoint in ("/api/validate", "/api/tree", "/api/map"):
                started = time.monotonic()
                status, raw = studio.post(endpoint, {"text": text, "path": "missions/m.yaml"})
                took = time.monotonic() - started
                assert took < 5.0, (key, written, endpoint, took)
                assert status == 200, raw
                assert SECRET not in raw and "hidden_content" not in raw and "internal error" not in raw, raw
                problems = json.loads(raw)["problems"]
                assert problems and problems[0]["line"] == 2 and "file" not in problems[0], (written, raw)
                assert f"'{written}'" in problems[0]["message"], problems[0]
    assert studio.process.poll() is None and studio.peak_rss_bytes() < 200e6


def test_the_studios_files_by_name_and_inside_the_folder_still_load(studio):
    for line in ("world: campus", "world: ../worlds/corridor.yaml", "world: ../missions/../worlds/corridor.yaml"):
        status, raw = studio.post("/api/validate", {"text": MISSION.format(line=line), "path": "missions/m.yaml"})
        assert (status, json.loads(raw)) == (200, {"problems": []}), line


def test_a_template_names_the_shipped_world_by_its_name_so_the_file_can_move(tmp_path):
    from beastbt.studio.files import StudioFolder
    from beastbt.studio.templates import TEMPLATES, template_text
    from beastbt.validate import validate_file
    folder = StudioFolder(tmp_path)
    for name, template in TEMPLATES.items():
        if template.world is None:
            continue
        text = template_text(folder, name, {"path": f"deep/down/{name}.yaml"})
        assert f"world: {Path(template.world).stem} " in text and ".venv" not in text and "../" not in text, text
        moved = tmp_path / "elsewhere" / f"{name}.yaml"  # shared, or saved anywhere: it still finds its world
        moved.parent.mkdir(exist_ok=True)
        moved.write_text(text)
        assert [p for p in validate_file(str(moved)) if p.severity == "error"] == [], name


def test_route_places_and_map_image_files_are_held_to_the_same_folder(tmp_path):
    from beastbt.core.errors import InvalidInput
    from beastbt.mission.model import load_mission
    folder = tmp_path / "folder"
    folder.mkdir()
    (tmp_path / "out.gpx").write_text("<gpx><rte><rtept lat='40.4' lon='-3.7'/></rte></gpx>\n")
    refs = FileRefs.inside(folder, "the studio's folder")
    for step in ("route: {file: /etc/passwd}", "route: {file: ../out.gpx}", "route: {file: /dev/zero}"):
        mission = folder / "m.yaml"
        mission.write_text(f"mission: m\nsteps:\n  - {step}\n")
        with pytest.raises(InvalidInput) as refused:
            load_mission(mission, refs=refs)
        text = refused.value.format()
        assert text.startswith("m.yaml:3:18: error: the route file '") or f"{mission}:3:" in text, text
        assert SECRET not in text and ("absolute path" in text or "climbs out" in text), text
    # a map inside the folder whose image is outside it, or a device: refused at the map's image line
    (folder / "maps").mkdir()
    shutil.copy(REPO / "maps" / "office.pgm", tmp_path / "outside.pgm")
    for image, says in (("../../outside.pgm", "climbs out of the studio's folder"), ("/dev/zero", "is an absolute path")):
        (folder / "maps" / "m.yaml").write_text(f"image: {image}\nresolution: 0.05\norigin: [0, 0, 0]\n")
        mission = folder / "m.yaml"
        mission.write_text("mission: m\nmap: maps/m.yaml\nplaces: {a: {x: 1 m, y: 1 m}}\nsteps:\n  - go_to: a\n")
        with pytest.raises(InvalidInput) as refused:
            load_mission(mission, refs=refs)
        assert f"m.yaml:1:8: error: the map image '{image}' {says}" in refused.value.format(), refused.value.format()
    # on the command line the same map image is read (the user's own disk)
    (folder / "maps" / "m.yaml").write_text("image: ../../outside.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    assert load_mission(folder / "m.yaml").map_grid is not None


def test_a_file_over_its_kinds_cap_is_refused_at_the_key_before_it_is_parsed(tmp_path):
    from beastbt.core.errors import InvalidInput
    from beastbt.mission.model import load_mission
    big = tmp_path / "big.yaml"
    big.write_text("world: big\nwalls:\n" + "  - [0, 0, 1, 1]\n" * (WORLD.max_bytes // 17 + 1))
    mission = tmp_path / "m.yaml"
    mission.write_text(MISSION.format(line="world: big.yaml"))
    started = time.monotonic()
    with pytest.raises(InvalidInput) as refused:
        from beastbt.mission.mission_world import load_mission_world
        load_mission_world(load_mission(mission, refs=FileRefs.inside(tmp_path, "the studio's folder")))
    assert time.monotonic() - started < 2.0  # refused from its size, not parsed (a megabyte of YAML takes seconds)
    assert "m.yaml:2:8: error: the world file 'big.yaml' is " in refused.value.format()
    assert "MB: a world file is read up to 1 MB" in refused.value.format()


def test_a_try_reads_the_files_its_mission_names_only_inside_the_folder(studio):
    status, raw = studio.post("/api/try", {"text": MISSION.format(line="world: ../../outside.yaml"),
                                           "path": "missions/m.yaml", "speed": "max"})
    assert status == 200, raw
    run_id = json.loads(raw)["run_id"]
    state = wait_for(lambda: (lambda a: a if a["state"] == "ended" else None)(
        json.loads(studio.get(f"/api/try/{run_id}")[1])), 60.0, "the try ends", period_s=0.2)
    output = "\n".join(state["output"]) if isinstance(state["output"], list) else str(state["output"])
    assert state["exit_code"] == 2 and "hidden_content" not in output, state
    assert "the world file '../../outside.yaml' climbs out of the folder" in output, output
