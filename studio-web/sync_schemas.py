"""Copy the JSON Schemas of schemas/ beside the studio's page (beastbt/studio/page/schemas/), without npm.

The page's editor (monaco-yaml) loads a file's schema from there, and the schema's ``$ref``s to ``parts/`` resolve
beside it. ``studio-web/build.sh`` copies them too; run this alone after a schema changed (tests/test_studio_page.py
fails until the copies match).
"""

from __future__ import annotations

import shutil
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SOURCE = REPO / "schemas"
TARGET = REPO / "beastbt" / "studio" / "page" / "schemas"


def sync() -> list[str]:
    """Make TARGET hold exactly SOURCE's ``*.schema.json`` (top level and ``parts/``); the relative paths copied."""
    if TARGET.exists():
        shutil.rmtree(TARGET)
    copied = []
    for sub in ("", "parts"):
        (TARGET / sub).mkdir(parents=True, exist_ok=True)
        for path in sorted((SOURCE / sub).glob("*.schema.json")):
            shutil.copyfile(path, TARGET / sub / path.name)
            copied.append(str(Path(sub) / path.name))
    return copied


if __name__ == "__main__":
    print(f"copied {len(sync())} schemas to {TARGET.relative_to(REPO)}")
