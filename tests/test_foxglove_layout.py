"""``beastbt foxglove-layout``: the shipped Foxglove layout names only channels and fields that beastbt writes."""

from __future__ import annotations

import json
import re

import pytest

from beastbt import cli
from beastbt.recording.layout import LAYOUT_FILE
from beastbt.recording.schemas import CHANNELS
from conftest import REPO


def panels_in(node) -> list[str]:
    """The panel ids of a layout tree (Foxglove's mosaic: strings at the leaves)."""
    if isinstance(node, str):
        return [node]
    return panels_in(node["first"]) + panels_in(node["second"])


def field_exists(schema: dict, path: str) -> bool:
    """Whether a Foxglove message path's fields (``a.b[0][1]``) exist in a JSON schema."""
    node = schema
    for part in re.findall(r"\.([A-Za-z_][A-Za-z0-9_]*)|\[\d+\]", path):
        if part:  # a field
            props = node.get("properties", {})
            if part not in props:
                return False
            node = props[part]
        else:  # an index
            if "items" not in node:
                return False
            node = node["items"]
    return True


def test_the_command_prints_the_shipped_layout(capsys):
    assert cli.main(["foxglove-layout"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json.loads(LAYOUT_FILE.read_text(encoding="utf-8"))
    assert '"foxglove_layout/*.json"' in (REPO / "pyproject.toml").read_text()  # shipped with the package


def test_every_panel_is_placed_once_and_the_promised_panels_are_there():
    layout = json.loads(LAYOUT_FILE.read_text(encoding="utf-8"))
    placed = panels_in(layout["layout"])
    assert sorted(placed) == sorted(layout["configById"]) and len(set(placed)) == len(placed)
    kinds = sorted(p.split("!")[0] for p in placed)
    assert kinds == ["3D", "Image", "Plot", "Plot", "RosOut", "map"]


def test_every_topic_and_plotted_field_is_one_beastbt_records():
    config = json.loads(LAYOUT_FILE.read_text(encoding="utf-8"))["configById"]
    topics = set(config["3D!beastbt"]["topics"]) | set(config["map!beastbt"]["topicColors"])
    topics |= {config["map!beastbt"]["followTopic"], config["RosOut!beastbt"]["topicToRender"]}
    image = config["Image!beastbt"]["imageMode"]
    topics |= {image["imageTopic"], image["calibrationTopic"], *image["annotations"]}
    assert topics <= set(CHANNELS), topics - set(CHANNELS)
    for plot in ("Plot!speed", "Plot!errors"):
        for series in config[plot]["paths"]:
            topic, _, rest = series["value"].partition(".")
            assert topic in CHANNELS, series["value"]
            assert field_exists(CHANNELS[topic], "." + rest), series["value"]
    assert not field_exists(CHANNELS["/cmd/gate"], ".linear_speed")  # the check can fail


def test_a_robots_own_frame_names_go_into_the_3d_view(tmp_path, capsys):
    profile = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    robot = tmp_path / "named.yaml"
    robot.write_text(profile + "\nframes: {map: world, base_link: beast/base_link}\n", encoding="utf-8")
    assert cli.main(["foxglove-layout", "--robot", str(robot)]) == 0
    three_d = json.loads(capsys.readouterr().out)["configById"]["3D!beastbt"]
    assert three_d["followTf"] == "beast/base_link" and three_d["layers"]["grid"]["frameId"] == "world"
    assert cli.main(["foxglove-layout", "--robot", str(tmp_path / "missing.yaml")]) == 2


def test_a_misspelt_frame_name_is_refused_with_its_place(tmp_path, capsys):
    profile = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    robot = tmp_path / "typo.yaml"
    robot.write_text(profile + "\nframes: {base_lnk: beast}\n", encoding="utf-8")
    assert cli.main(["validate", str(robot)]) == 2
    err = capsys.readouterr().err
    assert f"{robot}:" in err and "base_lnk" in err


def test_the_image_panel_draws_the_detections_and_the_3d_view_the_tags():
    config = json.loads(LAYOUT_FILE.read_text(encoding="utf-8"))["configById"]
    assert config["Image!beastbt"]["imageMode"]["annotations"]["/camera/detections"]["visible"] is True
    assert config["3D!beastbt"]["topics"]["/camera/tags"]["visible"] is True
