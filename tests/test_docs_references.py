"""What the README, the docs and the shipped examples cite exists: no file a reader would look for in vain."""

from __future__ import annotations

import re

import pytest

from conftest import REPO

READ_BY_PEOPLE = sorted([REPO / "README.md", *(REPO / "docs").rglob("*.md"), *(REPO / "missions").rglob("*.yaml"),
                         *(REPO / "robots").glob("*.yaml"), *(REPO / "worlds").glob("*.yaml")])
TOP = ("docs", "missions", "robots", "worlds", "benchmarks", "schemas", "beastbt", "tests", "maps")
CITED = re.compile(r"(?<![\w./-])((?:%s)/[\w./-]*\w)" % "|".join(TOP))
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
MD_NAME = re.compile(r"(?<![\w./-])([A-Za-z_][\w-]*\.md)\b")


PLACEHOLDERS = {"missions/x.yaml", "beastbt/fleet/estop", "beastbt/fleet/station", "beastbt/fleet/sim/poses"}
"""Names that stand for the reader's own file ("beastbt run missions/x.yaml"), and the fleet's Zenoh keys
(docs/fleet.md), which look like paths but are not files."""


def _exists(path: str, beside) -> bool:
    if path in PLACEHOLDERS or any(ch in path for ch in "*<>{}$") or path.startswith(("http:", "https:", "mailto:")):
        return True  # a pattern or a placeholder, not a file
    return (REPO / path).exists() or (beside / path).exists()


@pytest.mark.parametrize("doc", READ_BY_PEOPLE, ids=lambda p: str(p.relative_to(REPO)))
def test_every_file_a_page_cites_exists(doc):
    text = doc.read_text(encoding="utf-8")
    cited = set(CITED.findall(text)) | set(LINK.findall(text)) | set(MD_NAME.findall(text))
    cited = {c.rstrip(".") for c in cited}
    missing = sorted(c for c in cited if not _exists(c, doc.parent) and not any(
        (d / c).exists() for d in (REPO, REPO / "docs", REPO / "docs" / "hardware")))
    assert not missing, f"{doc.relative_to(REPO)} cites what does not exist: {missing}"


def test_the_readme_lists_every_command_and_every_option_of_run():
    from beastbt import cli
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    for name in cli.COMMANDS:
        assert f"`beastbt {name}" in readme, f"the README's command table has no 'beastbt {name}'"
    run, _ = cli.command_parser("run")
    options = [o for action in run._actions for o in action.option_strings if o.startswith("--") and o != "--help"]
    missing = [o for o in options if f"`{o}" not in readme and f"{o}`" not in readme and f" {o}," not in readme]
    assert not missing, f"options of 'beastbt run' the README does not list: {missing}"
