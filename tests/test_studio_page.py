"""The studio's built page (beastbt/studio/page/) is the one its sources build, so tests and ``pip install .`` need
no npm: ``studio-web/build.sh`` writes ``page/BUILD_INFO.json`` with a SHA-256 over the sources it was built from
(package.json, package-lock.json, build.mjs, tsconfig.json and src/), and the list of the files it wrote.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from conftest import REPO

WEB = REPO / "studio-web"
PAGE = REPO / "beastbt" / "studio" / "page"
REBUILD = "run studio-web/build.sh (npm ci && npm run build) and commit beastbt/studio/page/"


def source_files() -> list[str]:
    """The files the bundle is made from, in build.mjs's order (sourceFiles())."""
    files = ["package.json", "package-lock.json", "build.mjs", "tsconfig.json"]

    def walk(rel: str) -> None:
        for name in sorted(p.name for p in (WEB / rel).iterdir()):
            child = f"{rel}/{name}"
            if (WEB / child).is_dir():
                walk(child)
            else:
                files.append(child)
    walk("src")
    return files


def source_hash() -> str:
    """build.mjs's sourceHash(): each file's relative path, a newline, its bytes, a newline."""
    h = hashlib.sha256()
    for rel in source_files():
        h.update(rel.encode() + b"\n")
        h.update((WEB / rel).read_bytes())
        h.update(b"\n")
    return h.hexdigest()


def build_info() -> dict:
    path = PAGE / "BUILD_INFO.json"
    assert path.is_file(), f"no {path.relative_to(REPO)}: {REBUILD}"
    return json.loads(path.read_text(encoding="utf-8"))


def test_the_committed_page_was_built_from_the_committed_sources():
    info = build_info()
    assert info["sources"] == source_files(), f"the page was built from other files: {REBUILD}"
    assert info["source_sha256"] == source_hash(), f"studio-web/ changed since the page was built: {REBUILD}"


def test_every_file_the_build_wrote_is_there_whole():
    info = build_info()
    for name in ("index.html", "studio.js", "studio.css", "editor.worker.js", "yaml.worker.js", "elk-worker.js",
                 "THIRD_PARTY_LICENSES.txt"):
        assert name in info["files"], f"the build wrote no {name}"
    for name, size in info["files"].items():
        path = PAGE / name
        assert path.is_file(), f"{path.relative_to(REPO)} is missing: {REBUILD}"
        assert path.stat().st_size == size, f"{path.relative_to(REPO)} is not the one built: {REBUILD}"


def test_the_page_loads_nothing_from_outside_its_folder():
    html = (PAGE / "index.html").read_text(encoding="utf-8")
    for attr in ('src="', 'href="'):
        for part in html.split(attr)[1:]:
            url = part.split('"', 1)[0]
            assert "//" not in url and not url.startswith("/"), f"index.html loads {url}: the page must work offline"
            assert (PAGE / url).is_file(), f"index.html loads {url}, which the build did not write"
