"""The front door: the package lists every folder, the README has its two Quick start lines, CI runs them."""

from __future__ import annotations

import re

from conftest import REPO


def test_every_package_folder_is_listed_in_pyproject():
    text = (REPO / "pyproject.toml").read_text()
    block = re.search(r"^packages = \[(.*?)\]", text, re.S | re.M).group(1)
    listed = set(re.findall(r'"([^"]+)"', block))
    on_disk = {"beastbt"} | {f"beastbt.{p.name}" for p in (REPO / "beastbt").iterdir()
                             if p.is_dir() and (p / "__init__.py").exists()}
    assert on_disk <= listed


def test_every_package_has_a_docstring():
    for init in (REPO / "beastbt").glob("*/__init__.py"):
        text = init.read_text().strip()
        assert text.startswith('"""') and "TODO" not in text, init


def quick_start_lines() -> list[str]:
    readme = (REPO / "README.md").read_text()
    section = re.search(r"## Quick start\n(.*?)\n## ", readme, re.S).group(1)
    block = re.search(r"```(?:sh|bash|console)?\n(.*?)```", section, re.S).group(1)
    return [ln for ln in block.splitlines() if ln.strip() and not ln.strip().startswith("#")]


def test_readme_quick_start_has_exactly_two_command_lines():
    lines = quick_start_lines()
    assert len(lines) == 2
    assert "missions/patrol.yaml" in lines[0] and "pytest" in lines[1] and "[test]" in lines[1]


def test_ci_runs_the_readme_test_line_verbatim():
    ci = (REPO / ".ci" / "run").read_text()
    assert quick_start_lines()[1].strip() in ci


def test_the_consoles_page_files_are_package_data():
    import fnmatch

    from beastbt.live.console_server import PAGE_FILES
    text = (REPO / "pyproject.toml").read_text()  # no tomllib on Python 3.10
    data = re.search(r"^\[tool\.setuptools\.package-data\]\n(.*?)(?:\n\[|\Z)", text, re.S | re.M).group(1)
    shipped = re.findall(r'"([^"]+)"', re.search(r'^"beastbt\.live" = \[(.*?)\]', data, re.M).group(1))
    assert shipped
    for name in ["index.html", *PAGE_FILES]:  # the page, its script, style and icon: in the wheel, no CDN
        assert (REPO / "beastbt" / "live" / "console_page" / name).is_file(), name
        assert any(fnmatch.fnmatch(f"console_page/{name}", pattern) for pattern in shipped), name


def test_the_studios_page_is_package_data_with_its_nested_folders():
    import fnmatch

    text = (REPO / "pyproject.toml").read_text()
    data = re.search(r"^\[tool\.setuptools\.package-data\]\n(.*?)(?:\n\[|\Z)", text, re.S | re.M).group(1)
    shipped = re.findall(r'"([^"]+)"', re.search(r'^"beastbt\.studio" = \[(.*?)\]', data, re.M).group(1))
    page = REPO / "beastbt" / "studio" / "page"
    files = [p.relative_to(page.parent).as_posix() for p in page.rglob("*") if p.is_file()]
    assert "page/index.html" in files
    for name in files:
        assert any(fnmatch.fnmatch(name, pattern) for pattern in shipped), name
    # the bundle's files however deep the build puts them: setuptools' '*' stops at a '/', '**' does not
    assert "page/**/*" in shipped
