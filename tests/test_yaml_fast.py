"""libyaml composes plain documents exactly as PyYAML's own composer does (core.yaml_source's fast path).

:func:`beastbt.core.yaml_source._compose_fast` hands a document without
aliases, tags, escapes, tabs or directives to PyYAML's C binding (start-up
time); everything else, and everything libyaml refuses, goes to PyYAML's
Python composer as before. Here both compose every YAML file of the repository
and a set of tricky documents, node by node (kind, tag, value, style, flow
style, start and end line and column), and :func:`load_yaml` gives the same
data, positions and comments either way.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import pytest
import yaml

from beastbt.core import yaml_source
from beastbt.core.errors import InvalidInput
from beastbt.core.yaml_source import _compose_fast, _CountingLoader, load_yaml
from conftest import REPO

FILES = sorted(p for folder in ("missions", "robots", "worlds", "maps", "tests") for p in (REPO / folder).rglob("*.y*ml")
               if p.suffix in (".yaml", ".yml"))

TRICKY = [
    "a: plain # a comment\nb: 'single'\nc: \"double\"\nd: |\n  literal\n  text\ne: >-\n  folded\n  text\n",
    "steps:\n  - drive: {distance: 0,5 m}\n  - turn: [1, 2, {x: y}]\n  - - nested\n    - - deeper\n",
    "say: look here: now\nq: \"Drive forward?\"\nempty:\nnull_word: null\ntilde: ~\n",
    "n: [1e400, .nan, .inf, -.inf, 0x1F, 0o17, 1_000, 3.5e-3, +7]\nb: [yes, no, on, off, true, False, y, n]\n",
    "when: 2024-01-02\nstamp: 2024-01-02T03:04:05Z\nv: 1.0.0\nt: 12:30\n",
    "key with spaces: 1\n? complex\n: value\n'quoted key': 2\n",
    "a: 1\r\nb:\r\n  - x\r\n  - y # c\r\n",
    "multi: this is\n  a plain scalar\n  on three lines\nafter: 1\n",
    "---\nmission: m\n...\n",
    "mission: é漢字 # unicode\nplaces: {café: {lat: 1, lon: 2}}\n",
    "a: 1\na: 2\n",
    "",
    "# only a comment\n",
    "- a\n- b: 1\n  c: 2\n-\n  - d\n",
    "a: {b: 1\n",
    "a: b: c\n",
    "a:\n  - 1\n - 2\n",
    "a: 'unterminated\n",
    "--- a\n--- b\n",
    "a: [1, 2,]\nb: {c: 1,}\n",
    "text: >+\n  keep\n\n\nnext: 1\n",
    "k: 'it''s'\nl: \"say \"\n",
    # Documents PyYAML refuses (libyaml must not read them instead) and edge cases of indentation and flow.
    "a: - b\n", "- a\nb: 1\n", "a:\n  b\n  c: 1\n", "[a, b]: 1\n", "a: b\n  c: d\n", "{a: 1} b\n", "a: 'x' y\n",
    "@a: 1\n", "`a: 1\n", "a: |\n x\n  y\n z\n", "a: b\n- c\n", "a: 1\n b: 2\n", "key: [a, b\nc: 1\n",
    "a: {b: c, d}\n", "? a\n? b\n", "- - - a\n  - b\n", "a: >\n  x\n y\n", "{a: [}\n", "a: ]\n", "a: ,b\n",
    "a: |2-\n   x\n", "---\n---\n", "a: b\n...\nc: d\n", "a: [b, c]d\n", "foo: bar\n baz\n",
    "a: \"multi\n  line\"\n", "a: 'multi\n\n  line'\n",
]


def _pure(text: str) -> Optional[yaml.Node]:
    loader = _CountingLoader(text)
    try:
        return loader.get_single_node()
    finally:
        loader.dispose()


def _nodes(root: Optional[yaml.Node]) -> list[tuple]:
    out: list[tuple] = []

    def walk(node: yaml.Node) -> None:
        marks = (node.start_mark.line, node.start_mark.column, node.end_mark.line, node.end_mark.column)
        value = node.value if isinstance(node, yaml.ScalarNode) else None
        out.append((type(node).__name__, node.tag, value, getattr(node, "style", None),
                    getattr(node, "flow_style", None), marks))
        if isinstance(node, yaml.MappingNode):
            for key, item in node.value:
                walk(key)
                walk(item)
        elif isinstance(node, yaml.SequenceNode):
            for item in node.value:
                walk(item)

    if root is not None:
        walk(root)
    return out


def _same_as_pure(text: str) -> bool:
    """Whether libyaml took the document; when it did, its nodes are PyYAML's."""
    fast = _compose_fast(text)
    if fast is None:
        return False
    assert _nodes(fast) == _nodes(_pure(text))
    return True


def test_the_fast_path_is_used_for_the_missions_and_profiles() -> None:
    for name in ("missions/patrol.yaml", "robots/sim.yaml"):
        assert _compose_fast((REPO / name).read_text(encoding="utf-8")) is not None, name


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_repository_file_composes_as_pyyaml_does(path: Path) -> None:
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        pytest.skip("not UTF-8 text")
    try:
        _same_as_pure(text)
    except yaml.YAMLError:
        pytest.skip("not YAML PyYAML reads (a fixture of a refused file)")


@pytest.mark.parametrize("text", TRICKY)
def test_tricky_documents_compose_as_pyyaml_does_or_go_to_pyyaml(text: str) -> None:
    try:
        _pure(text)
        pure_ok = True
    except yaml.YAMLError:
        pure_ok = False
    taken = _same_as_pure(text) if pure_ok else _compose_fast(text) is not None
    assert not (taken and not pure_ok)  # a document PyYAML refuses is never read by libyaml instead


@pytest.mark.parametrize("text", ["a: *x\n", "a: &x 1\nb: *x\n", "a: !!int 2 s\n", "a: \"\\U0011FFFF\"\n",
                                  "a:\t1\n", "\ufeffa: 1\n", "%YAML 1.1\n---\na: 1\n", "a: 1\u2028b: 2\n",
                                  "a: " + "[" * 250 + "]" * 250 + "\n", "- " * 250 + "x\n", "a: \x07\n"])
def test_aliases_tags_escapes_tabs_directives_and_deep_nesting_go_to_pyyaml(text: str) -> None:
    assert _compose_fast(text) is None


def _loaded(path: Path, fast: bool, monkeypatch: pytest.MonkeyPatch) -> Any:
    with monkeypatch.context() as m:
        if not fast:
            m.setattr(yaml_source, "_compose_fast", lambda text: None)
        try:
            doc = load_yaml(path, require_mapping=False)
        except InvalidInput as exc:
            return [p.format() for p in exc.problems]
        return doc.data, doc.positions, doc.key_positions, doc.comments_after


@pytest.mark.parametrize("path", [p for p in FILES if p.parts[-2] in ("missions", "robots", "worlds")],
                         ids=lambda p: str(p.relative_to(REPO)))
def test_load_yaml_gives_the_same_document_either_way(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert _loaded(path, True, monkeypatch) == _loaded(path, False, monkeypatch)


@pytest.mark.parametrize("text", TRICKY)
def test_load_yaml_of_tricky_text_is_the_same_either_way(text: str, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "doc.yaml"
    path.write_bytes(text.encode("utf-8"))
    assert _loaded(path, True, monkeypatch) == _loaded(path, False, monkeypatch)
