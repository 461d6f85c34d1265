"""The schemas as editors use them (VS Code YAML, Neovim... through the YAML language server).

An editor reads a file's schema from its first line (``# yaml-language-server:
$schema=../schemas/mission.schema.json``) and resolves the schema's ``$ref``
beside it, unless the schema states an ``$id`` (which made ``parts/x.schema.json``
a web address that does not exist). Without node these tests check the schemas
themselves: every ``$ref`` resolves to a shipped file; every step, condition and
field has a title, a description and an example, and the examples validate;
values with units have a pattern and say what they expect. With node and
``yaml-language-server`` (see ``tests/yaml_ls.py``; ``.ci/run`` installs it) they
run the server headless over the shipped missions, robots, worlds and the docs'
examples, as an editor would.
"""

from __future__ import annotations

import json
import os
import re
from typing import Any, Iterator

import pytest
import yaml

from beastbt.core.resources import data_dir
from beastbt.core.schema_check import validator_for, validator_of
from beastbt.core.units import KINDS
from beastbt.core.unit_fields import SUFFIX_UNITS
from beastbt.mission.explain import steps_and_help
from conftest import REPO
from yaml_ls import ENV, YamlLanguageServer, find_server, text_of

SCHEMA_DIR = data_dir("schemas")


def schema_names() -> list[str]:
    names = [e.name for e in SCHEMA_DIR.iterdir() if e.name.endswith(".json")]
    names += ["parts/" + e.name for e in (SCHEMA_DIR / "parts").iterdir() if e.name.endswith(".json")]
    return sorted(names)


SCHEMAS = schema_names()


def load(name: str) -> dict:
    node: Any = SCHEMA_DIR
    for part in name.split("/"):
        node = node / part
    return json.loads(node.read_text(encoding="utf-8"))


def walk(node: Any, pointer: str = "") -> Iterator[tuple[str, Any]]:
    """(JSON pointer, node) for every node of a schema."""
    yield pointer, node
    if isinstance(node, dict):
        for key, value in node.items():
            yield from walk(value, f"{pointer}/{key}")
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from walk(value, f"{pointer}/{i}")


def follow(name: str, pointer: str) -> Any:
    node: Any = load(name)
    for part in filter(None, pointer.split("/")):
        node = node[int(part)] if isinstance(node, list) else node[part.replace("~1", "/").replace("~0", "~")]
    return node


def target_of(name: str, ref: str) -> tuple[str, str]:
    """The schema name and JSON pointer ``ref`` (written in schema ``name``) points to."""
    file, _, pointer = ref.partition("#")
    if not file:
        return name, pointer
    folder = name.rsplit("/", 1)[0] + "/" if "/" in name else ""
    parts: list[str] = []
    for part in (folder + file).split("/"):
        if part == "..":
            parts.pop()
        elif part not in ("", "."):
            parts.append(part)
    return "/".join(parts), pointer


@pytest.mark.parametrize("name", SCHEMAS)
def test_no_schema_states_an_id_that_would_send_its_refs_to_the_web(name):
    ids = [pointer for pointer, node in walk(load(name)) if isinstance(node, dict) and "$id" in node]
    assert not ids, f"{name}: $id at {ids}: editors would fetch the parts/ schemas from that address"


@pytest.mark.parametrize("name", SCHEMAS)
def test_every_ref_resolves_to_a_shipped_schema(name):
    for pointer, node in walk(load(name)):
        if not (isinstance(node, dict) and isinstance(node.get("$ref"), str)):
            continue
        ref = node["$ref"]
        assert "://" not in ref, f"{name}#{pointer}: {ref} is a remote address"
        target, fragment = target_of(name, ref)
        assert target in SCHEMAS, f"{name}#{pointer}: {ref} names no shipped schema"
        try:
            follow(target, fragment)
        except (KeyError, IndexError, ValueError):
            pytest.fail(f"{name}#{pointer}: {ref}: no such place in {target}")


# -- values with units: a pattern and words an editor shows ----------------------------------------------------

def unit_nodes(name: str) -> Iterator[tuple[str, dict, str]]:
    """(pointer, node, unit kind) for every schema node that takes a value with a unit."""
    defs = load(name).get("$defs", {})
    for pointer, node in walk(load(name)):
        if not isinstance(node, dict):
            continue
        if "x-unit-kind" in node:
            yield pointer, node, node["x-unit-kind"]
        for key, prop in (node.get("properties") or {}).items():
            suffix = next((s for s in sorted(SUFFIX_UNITS, key=len, reverse=True) if key.endswith(s)), None)
            if suffix is None or "_per_" in key or name in ("mission.schema.json", "summary.schema.json") \
                    or not isinstance(prop, dict):
                continue
            ref = prop.get("$ref") or (prop.get("items") or {}).get("$ref", "")
            assert prop.get("type") != "number" and (prop.get("items") or {}).get("type") != "number", \
                f"{name}#{pointer}/properties/{key}: a number knob with a unit in its name takes '500 ms' too: " \
                f"refer to a unit in $defs"
            if ref.startswith("#/$defs/") and "pattern" in defs[ref.rsplit("/", 1)[1]]:
                yield f"{pointer}/properties/{key}", defs[ref.rsplit("/", 1)[1]], SUFFIX_UNITS[suffix][0]


def test_values_with_units_have_a_pattern_and_say_what_they_expect():
    seen = set()
    for name in SCHEMAS:
        for pointer, node, kind in unit_nodes(name):
            seen.add(kind)
            where = f"{name}#{pointer}"
            message = node.get("patternErrorMessage", "")
            assert f"{kind.replace('_', ' ')} such as '" in message, f"{where}: {message!r}"
            assert node.get("errorMessage") == message, where
            if kind not in KINDS:
                continue
            for unit in KINDS[kind].factors:
                assert re.match(node["pattern"], f"1.5 {unit}"), f"{where}: '1.5 {unit}' does not match"
            assert not re.match(node["pattern"], "3 meters"), where
            assert f"such as '{KINDS[kind].example}'" in message, f"{where}: {message!r}"
    assert {"distance", "duration", "speed", "angle", "turn_rate", "frequency", "voltage"} <= seen


def test_a_profile_knob_named_with_its_unit_takes_a_value_with_a_unit_in_the_schema_too():
    """``timeout_s: 500 ms`` is read by beastbt (unit_fields), so the schema editors use must not call it wrong."""
    watchdog = validator_for("parts/watchdog.schema.json")
    assert watchdog.is_valid({"timeout_s": "400 ms"}) and watchdog.is_valid({"timeout_s": 0.4})
    assert not watchdog.is_valid({"timeout_s": "400 meters"})
    robot = load("robot.schema.json")
    assert robot["properties"]["limits"]["properties"]["max_speed_mps"]["$ref"] == "#/$defs/metres_per_second"


def test_beastbts_own_errors_for_a_knob_with_a_unit_say_what_to_write(tmp_path):
    """The knob's schema now takes text too (for editors); beastbt still says a number, and how to write one."""
    from beastbt.core.errors import InvalidInput
    from beastbt.robot.profile import load_profile
    text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8") + "watchdog: {timeout_s: yes}\n"
    (tmp_path / "p.yaml").write_text(text, encoding="utf-8")
    with pytest.raises(InvalidInput) as caught:
        load_profile(tmp_path / "p.yaml")
    said = caught.value.format()
    assert "error: expected a number in 'timeout_s', got true/false" in said, said
    assert "hint: write a number of seconds, or a duration such as '2 s' (units: s, ms, min, h)" in said, said


def test_beastbts_own_error_for_an_acceleration_names_what_it_expects(write_mission):
    from beastbt.core.errors import InvalidInput
    from beastbt.mission.model import load_mission
    with pytest.raises(InvalidInput) as caught:
        load_mission(write_mission("mission: m\nlimits: {acceleration: 2 m/s}\nsteps: [stop]\n"))
    said = caught.value.format()
    assert "error: 'acceleration': expected an acceleration such as '0.5 m/s2' (units: m/s2), got '2 m/s'" in said


# -- what an editor shows: a title, a description and an example for every step and field ----------------------

EDITED = [name for name in SCHEMAS if name != "summary.schema.json"]  # the summary is written by beastbt, not by people
MISSION = load("mission.schema.json")
YAML_BLOCK = "```yaml\n"


def yaml_examples(markdown: str) -> list[str]:
    return [block.split("```", 1)[0] for block in markdown.split(YAML_BLOCK)[1:]]


def branches(kind: str) -> list[dict]:
    return MISSION["$defs"][kind]["anyOf"]


def keyword_of(branch: dict) -> str:
    return branch["const"] if "const" in branch else branch["required"][0]


def mission_problems(steps: Any) -> list[str]:
    return [e.message for e in validator_for("mission.schema.json").iter_errors({"mission": "example", "steps": steps})]


@pytest.mark.parametrize("kind", ["step", "condition"])
def test_every_step_and_condition_has_a_title_a_description_and_examples_that_validate(kind):
    for branch in branches(kind):
        words = branch.get("enum") or [keyword_of(branch)]
        title = branch.get("title", "")
        assert branch.get("description"), words
        assert title and (kind == "condition" and "enum" in branch or title.startswith(f"{words[0]}: ")), \
            f"{words}: the title {title!r} should read '{words[0]}: what it does' (editors list it so)"
        examples = yaml_examples(branch.get("markdownDescription", ""))
        assert examples, f"{words}: no ```yaml example in markdownDescription"
        for text in examples:
            steps = yaml.safe_load(text)
            assert not mission_problems(steps), f"{words}: the example does not validate:\n{text}"
            assert any(w in text for w in words), f"{words}: the example does not use it:\n{text}"


def test_every_step_keyword_value_has_a_title_and_a_description():
    for branch in branches("step"):
        if "const" in branch:
            continue
        value = branch["properties"][keyword_of(branch)]
        assert value.get("title") and value.get("description"), keyword_of(branch)


def resolved(node: dict, defs: dict) -> dict:
    ref = node.get("$ref", "")
    return {**defs[ref.rsplit("/", 1)[1]], **node} if ref.startswith("#/$defs/") else node


def fields(name: str) -> Iterator[tuple[str, str, Any]]:
    """(pointer, key, schema) of every property of every object in schema ``name``."""
    for pointer, node in walk(load(name)):
        if isinstance(node, dict) and isinstance(node.get("properties"), dict) and not pointer.endswith("/properties"):
            for key, prop in node["properties"].items():
                yield f"{pointer}/properties/{key}", key, prop


def has_example(prop: dict) -> bool:
    if any(k in prop for k in ("examples", "default", "enum", "const")):
        return True
    if YAML_BLOCK in prop.get("markdownDescription", ""):
        return True
    if prop.get("type") in ("object", "array", "boolean") or "properties" in prop:
        return True  # a section (its fields have examples), a list, true/false
    ref = prop.get("$ref", "")
    return ref.endswith((".json", "/steps", "/condition", "/then_action", "/count", "/place"))


@pytest.mark.parametrize("name", EDITED)
def test_every_field_has_a_title_a_description_and_an_example(name):
    defs = load(name).get("$defs", {})
    missing = []
    for pointer, key, prop in fields(name):
        if not isinstance(prop, dict):
            continue  # 'true': anything goes
        full = resolved(prop, defs)
        if not prop.get("title"):
            missing.append(f"{pointer}: no title")
        if not full.get("description"):
            missing.append(f"{pointer}: no description")
        if not has_example(full):
            missing.append(f"{pointer}: no example (examples, a default, or ```yaml in markdownDescription)")
    assert not missing, f"{name}:\n" + "\n".join(missing)


@pytest.mark.parametrize("name", EDITED)
def test_every_example_fits_its_own_schema(name):
    wrong = []
    for pointer, node in walk(load(name)):
        if isinstance(node, dict) and isinstance(node.get("examples"), list) and "/properties/examples" not in pointer:
            check = validator_of({"$ref": f"https://beastbt.dev/schemas/{name}#{pointer}"}, "example-check.json")
            for example in node["examples"]:
                errors = [e.message for e in check.iter_errors(example)]
                if errors:
                    wrong.append(f"{pointer}: {example!r}: {errors}")
    assert not wrong, f"{name}:\n" + "\n".join(wrong)


# -- in an editor: the YAML language server, headless ------------------------------------------------------------

SCHEMA_LINE = re.compile(r"^# yaml-language-server: \$schema=(\S+)$", re.M)
SHIPPED = sorted(p for folder in ("missions", "robots", "worlds") for p in (REPO / folder).glob("*.yaml"))
SCHEMA_OF_FOLDER = {"missions": "mission", "robots": "robot", "worlds": "world"}


def test_every_shipped_file_names_its_schema_on_its_first_line():
    for path in SHIPPED:
        first = path.read_text(encoding="utf-8").splitlines()[0]
        want = f"# yaml-language-server: $schema=../schemas/{SCHEMA_OF_FOLDER[path.parent.name]}.schema.json"
        assert first == want, f"{path.relative_to(REPO)}: the first line should be {want!r} (editors check with it)"


TASK_PARAMETER = re.compile(r":\s*\$[A-Za-z_]")
"""``wait: $hold`` in a task with params: beastbt puts the default in before it checks; the schema cannot say so."""


def doc_examples() -> list[tuple[str, str]]:
    """(name, text) of the YAML examples of the docs that name the mission schema, or are missions of the language doc
    (but for those with task parameters, which an editor flags: known, see TASK_PARAMETER)."""
    out = []
    for doc in sorted((REPO / "docs").glob("*.md")) + [REPO / "README.md"]:
        for i, block in enumerate(re.findall(r"```yaml\n(.*?)```", doc.read_text(encoding="utf-8"), re.S)):
            if SCHEMA_LINE.search(block) or (doc.name == "mission-language.md" and re.search(r"^mission:", block, re.M)
                                             and not TASK_PARAMETER.search(block)):
                out.append((f"{doc.stem}-{i}", block))
    return out


DOC_EXAMPLES = doc_examples()


@pytest.fixture(scope="module")
def editor():
    program = find_server()
    if program is None and os.environ.get(ENV):
        pytest.fail(f"{ENV}={os.environ[ENV]} names no yaml-language-server to run (or node is missing)")
    if program is None:
        pytest.skip(f"no node or yaml-language-server (npm install yaml-language-server; set {ENV} to the folder)")
    with YamlLanguageServer(program, REPO) as server:
        yield server


def messages(diagnostics: list[dict]) -> list[str]:
    return [f"{d['range']['start']['line'] + 1}:{d['range']['start']['character'] + 1}: {d['message']}"
            for d in diagnostics]


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_the_editor_finds_nothing_wrong_in_a_shipped_file(editor, path):
    text = path.read_text(encoding="utf-8")
    assert SCHEMA_LINE.search(text)
    assert messages(editor.diagnostics(editor.open(path, text))) == []


@pytest.mark.parametrize("name, text", DOC_EXAMPLES, ids=[n for n, _ in DOC_EXAMPLES])
def test_the_editor_finds_nothing_wrong_in_an_example_of_the_docs(editor, name, text):
    if not SCHEMA_LINE.search(text):
        text = "# yaml-language-server: $schema=../schemas/mission.schema.json\n" + text
    uri = editor.open(REPO / "docs" / f"__example_{name}.yaml", text)
    assert messages(editor.diagnostics(uri)) == []


MISSION_HEAD = "# yaml-language-server: $schema=../schemas/mission.schema.json\nmission: editor_test\n"


def test_a_unit_mistake_says_what_the_editor_expects(editor):
    text = MISSION_HEAD + "steps:\n  - drive: {distance: 3 meters}\n  - turn: {angle: 90}\n  - wait: 2 s\n"
    found = messages(editor.diagnostics(editor.open(REPO / "missions" / "__editor_units.yaml", text)))
    assert len(found) == 2, found
    assert found[0].startswith("4:23: ") and "distance such as '3 m'" in found[0], found
    assert found[1].startswith("5:19: ") and "angle such as '90 deg'" in found[1] and "not a bare number" in found[1]
    assert not any("Expected number" in m or 'Expected "number"' in m for m in found)


def test_a_count_that_is_not_one_says_whole_number_or_forever(editor):
    text = MISSION_HEAD + ("steps:\n  - repeat: {times: three, steps: [stop]}\n"
                           "  - repeat: {times: forever, steps: [stop]}\n")
    found = messages(editor.diagnostics(editor.open(REPO / "missions" / "__editor_count.yaml", text)))
    assert found == ["4:21: Expected a whole number from 1 to 1000000, such as 3, or forever."], found


def test_completion_of_a_step_offers_every_step_by_its_title(editor):
    text = MISSION_HEAD + "steps:\n  - wait: 1 s\n  - \n"
    uri = editor.open(REPO / "missions" / "__editor_completion.yaml", text)
    items = editor.completion(uri, 4, 4)
    labels = [item["label"] for item in items]
    assert not [label for label in labels if label.startswith("object(")], labels
    for keyword in steps_and_help():
        branch = next(b for b in branches("step") if keyword_of(b) == keyword)
        if "const" in branch:
            assert keyword in labels, keyword  # a word alone: stop, return_home
        else:
            assert branch["title"] in labels, (keyword, labels)
    drive = next(item for item in items if item["label"].startswith("drive: "))
    assert "drive: {distance: 3 m" in text_of(drive.get("documentation")), drive


def test_hover_shows_a_steps_title_and_a_fields_own_title_description_and_example(editor):
    text = MISSION_HEAD + "steps:\n  - drive: {distance: 2 m, stuck_after: 3 s}\n"
    uri = editor.open(REPO / "missions" / "__editor_hover.yaml", text)
    editor.diagnostics(uri)
    assert "#### drive by distance" in editor.hover(uri, 3, 6)
    field = editor.hover(uri, 3, 15)
    assert "#### Distance" in field and "How far to drive straight" in field and "3 m" in field, field
    # a field with a keyword beside its $ref (x-default-from, a minimum) is shown by its own words, not its unit's
    stuck = editor.hover(uri, 3, 31)
    assert "#### Stuck after" in stuck and "Fail when no progress" in stuck, stuck
    profile = REPO / "robots" / "sim.yaml"
    uri = editor.open(profile)
    editor.diagnostics(uri)
    lines = profile.read_text(encoding="utf-8").splitlines()
    line = next(i for i, text in enumerate(lines) if "max_speed_mps:" in text)
    knob = editor.hover(uri, line, 4)
    assert "#### Max speed (m/s)" in knob and "Every command is clamped to it" in knob, knob


def robot_text(section: str) -> str:
    return (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8") + section


def test_a_robot_profile_is_checked_through_the_parts_schemas(editor):
    """The watchdog: and estimator: sections are schemas of their own in parts/: a wrong key there is found."""
    lines = len(robot_text("").splitlines())
    text = robot_text("watchdog:\n  timeout_s: 400 ms\n  check_period_sec: 0.02\n  estop_grace_s: 20 meters\n")
    found = messages(editor.diagnostics(editor.open(REPO / "robots" / "__editor_robot.yaml", text)))
    assert len(found) == 2, found
    assert any(m.startswith(f"{lines + 3}:3: ") and "check_period_sec" in m for m in found), found
    assert any(m.startswith(f"{lines + 4}:") and "duration such as '2 s'" in m for m in found), found


def test_a_world_is_checked_through_the_parts_schemas(editor):
    world = (REPO / "worlds" / "corridor.yaml").read_text(encoding="utf-8")
    world = "".join(line for line in world.splitlines(True) if not line.startswith("gps:"))  # ours replaces it
    text = world + "gps:\n  white_sigma: 1.0\n"
    found = messages(editor.diagnostics(editor.open(REPO / "worlds" / "__editor_world.yaml", text)))
    assert len(found) == 1 and "white_sigma" in found[0], found
