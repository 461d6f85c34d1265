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


STALE_PROMISES = {
    "Planning around obstacles is next": "go_to plans round obstacles (docs/navigation.md)",
    "Until the collision monitor\nexists": "the collision monitor exists (docs/obstacles.md)",
    "until the collision monitor exists": "the collision monitor exists (docs/obstacles.md)",
}
"""Sentences that promised, as still to come, what beastbt now does (issue 37 item 13): a reader believes them."""


@pytest.mark.parametrize("doc", [p for p in READ_BY_PEOPLE if p.suffix == ".md"], ids=lambda p: str(p.relative_to(REPO)))
def test_no_doc_promises_as_coming_what_is_already_there(doc):
    text = doc.read_text(encoding="utf-8")
    stale = [f"{said!r}: {why}" for said, why in STALE_PROMISES.items() if said in text]
    assert not stale, stale


def test_the_quick_start_says_how_long_the_test_suite_takes():
    """A new user who types the README's second line is told what to expect of it (issue 37 item 14)."""
    quick = (REPO / "README.md").read_text(encoding="utf-8").split("## Quick start", 1)[1].split("\n## ", 1)[0]
    assert re.search(r"takes about \d+ minutes on two cores", quick), quick
