"""The shipped JSON schemas have each key once per object: JSON readers keep the last of two silently, so a
duplicate hides an edit (a description or example written twice, one of them lost)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

SCHEMAS = sorted((Path(__file__).resolve().parent.parent / "schemas").rglob("*.json"))


def _no_duplicates(pairs: list) -> dict:
    keys = [k for k, _ in pairs]
    twice = sorted({k for k in keys if keys.count(k) > 1})
    assert not twice, f"keys written twice in one object: {twice}"
    return dict(pairs)


@pytest.mark.parametrize("path", SCHEMAS, ids=[p.name for p in SCHEMAS])
def test_a_schema_writes_each_key_once(path):
    json.loads(path.read_text(encoding="utf-8"), object_pairs_hook=_no_duplicates)
