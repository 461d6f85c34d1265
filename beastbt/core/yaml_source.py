"""YAML loading that remembers where every value came from.

PyYAML's composer gives each node a start mark; :func:`load_yaml` turns the
node tree into plain Python data and a map from each value's path (a tuple of
keys and list indices, as jsonschema reports them) to its line and column, so
that any later check can point at the exact place in the file. Tabs used for
indentation, duplicate keys, an empty file and a top level that is not a
mapping are reported here, with a hint.

What no file may do is refused here too, before anything walks the document:
aliases that expand it beyond a bound (a "billion laughs" file: PyYAML shares
an alias's node, so the blow-up would come when the tree is walked), numbers
that are not finite or are absurdly large, and values a YAML tag cannot read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Union

import math
import re

import yaml

from beastbt.core.errors import InvalidInput, Position, Problem

PathKey = tuple[Union[str, int], ...]

MAX_NESTING = 100
"""Most lists and mappings one inside another in a file (a step nested in a step takes about three):
deeper documents are refused with a position instead of exhausting Python's recursion."""


ALIAS_ALLOWANCE = 10_000
"""Values that aliases (``*name``) may add to a file beyond as many as it writes: with every alias expanded, a file
may hold at most twice the values written in it plus this many. Like Go's yaml.v3 (which bounds aliases relative to
the document) and SnakeYAML (which counts them), this keeps anchors for reuse (``<<: *slow``) and refuses an alias
bomb before it is expanded."""

MAX_NUMBER = 10 ** 15
"""Largest magnitude of any number in a file. No quantity a robot file describes comes near it (1e15 m is a hundred
times the distance to the Sun), and every whole number below it is exact as a float. Each field's own range, in the
schemas and the unit kinds, is much tighter."""

_INT_TAG = "tag:yaml.org,2002:int"
_FLOAT_TAG = "tag:yaml.org,2002:float"


@dataclass
class SourceDoc:
    """A YAML document as data plus the position of every value and every mapping key."""

    file: str
    data: Any
    positions: dict[PathKey, Position] = field(default_factory=dict)
    key_positions: dict[PathKey, Position] = field(default_factory=dict)
    comments_after: dict[PathKey, str] = field(default_factory=dict)
    """Unquoted text values followed by a ``#`` comment on the same line: YAML cut the text there."""

    def position(self, path: PathKey, key: bool = False) -> Position:
        """Where the value (or, with ``key=True``, the key) at ``path`` is; falls back to its parents."""
        path = tuple(path)
        if key and path in self.key_positions:
            return self.key_positions[path]
        while path:
            if path in self.positions:
                return self.positions[path]
            path = path[:-1]
        return self.positions.get((), Position(1, 1))

    def problem(self, path: PathKey, message: str, hint: str | None = None, key: bool = False) -> Problem:
        """A :class:`Problem` located at ``path`` in this document."""
        return Problem(self.file, self.position(path, key=key), message, hint)


def values_at_key(node: Any, key: str, path: PathKey = ()) -> list[tuple[PathKey, Any]]:
    """Every value stored under ``key`` in a document, with its path, in document order (not looking inside them)."""
    out: list[tuple[PathKey, Any]] = []
    if isinstance(node, dict):
        for k, v in node.items():
            if k == key:
                out.append((path + (k,), v))
            else:
                out.extend(values_at_key(v, key, path + (k,)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.extend(values_at_key(v, key, path + (i,)))
    return out


def _pos(mark: yaml.Mark) -> Position:
    return Position(mark.line + 1, mark.column + 1)


class _Builder:
    def __init__(self, doc: SourceDoc, text: str = "") -> None:
        self.doc = doc
        self.lines = text.splitlines()
        self.constructor = yaml.SafeLoader("")  # used only for scalar construction
        self.problems: list[Problem] = []
        self.too_deep = False

    def build(self, node: yaml.Node, path: PathKey) -> Any:
        self.doc.positions[path] = _pos(node.start_mark)
        if len(path) >= MAX_NESTING and isinstance(node, (yaml.MappingNode, yaml.SequenceNode)):
            if not self.too_deep:
                self.too_deep = True
                self.problems.append(Problem(
                    self.doc.file, _pos(node.start_mark),
                    f"nested too deeply: more than {MAX_NESTING} levels of lists and mappings (about "
                    f"{MAX_NESTING // 3} steps inside one another)",
                    "move the inner steps into a task under 'tasks:' and run it with 'do: <task>'"))
            return None
        if isinstance(node, yaml.MappingNode):
            # YAML merge keys (<<: *base): the merged pairs come first and the mapping's own keys override
            # them, as in PyYAML; only a key written twice in the mapping itself is a duplicate.
            own = {id(k) for k, _ in node.value if k.tag != "tag:yaml.org,2002:merge"}
            if node.flow_style and self._decimal_comma_split(node):
                return None
            self.constructor.flatten_mapping(node)
            out: dict = {}
            merged: set = set()
            for key_node, value_node in node.value:
                key = self.build_scalar_key(key_node)
                if id(key_node) not in own:
                    merged.add(key)
                elif key in merged:
                    merged.discard(key)
                    out.pop(key, None)
                if key in out and key in merged:
                    out.pop(key)  # a later merged mapping's value: the earlier one wins, as PyYAML orders them
                if key in out:
                    first = self.doc.key_positions[path + (key,)]
                    self.problems.append(Problem(
                        self.doc.file, _pos(key_node.start_mark),
                        f"duplicate key '{key}' (first defined at line {first.line})",
                        "each key may appear once in a mapping; merge the two or rename one",
                    ))
                    continue
                self.doc.key_positions[path + (key,)] = _pos(key_node.start_mark)
                out[key] = self.build(value_node, path + (key,))
            return out
        if isinstance(node, yaml.SequenceNode):
            return [self.build(child, path + (i,)) for i, child in enumerate(node.value)]
        value = self.scalar(node, path)
        if isinstance(value, str) and node.style is None and self.lines:
            end = node.end_mark
            rest = self.lines[end.line][end.column:] if end.line < len(self.lines) else ""
            if rest.lstrip().startswith("#"):
                self.doc.comments_after[path] = rest.lstrip()
        return value

    def _decimal_comma_split(self, node: yaml.MappingNode) -> bool:
        """A flow mapping where YAML split a decimal comma: ``{distance: 0,5 m}`` reads as ``distance: 0`` and a
        key ``5 m`` with no value. Said as a decimal comma (a problem added, True), not as an unknown key."""
        found = False
        pairs = node.value
        for (key, value), (next_key, next_value) in zip(pairs, pairs[1:]):
            if (isinstance(value, yaml.ScalarNode) and value.style is None and _DIGITS.match(value.value)
                    and isinstance(next_key, yaml.ScalarNode) and next_key.style is None
                    and _DIGITS_AND_UNIT.match(next_key.value)
                    and isinstance(next_value, yaml.ScalarNode) and next_value.value == ""):
                written = f"{value.value},{next_key.value}"
                self.problems.append(Problem(
                    self.doc.file, _pos(value.start_mark),
                    f"'{key.value}: {written}' has a decimal comma: inside {{...}} YAML splits it at the comma",
                    f"write '{key.value}: {value.value}.{next_key.value}' (a point, not a comma)"))
                found = True
        return found

    def build_scalar_key(self, node: yaml.Node) -> Any:
        if not isinstance(node, yaml.ScalarNode):
            self.problems.append(Problem(self.doc.file, _pos(node.start_mark), "a mapping key must be a plain word",
                                         "write keys as simple names like 'speed:'"))
            return f"<complex key at line {node.start_mark.line + 1}>"
        key = self.scalar(node, ())
        return key if isinstance(key, str) else node.value if key is None else str(key)

    def scalar(self, node: yaml.ScalarNode, path: PathKey) -> Any:
        """The value of a scalar node; None, with a problem, for one no file may hold (a non-finite or huge number,
        or a text its tag cannot read)."""
        label = _label(path)
        if node.tag == _INT_TAG and len(node.value.lstrip("+-").replace("_", "")) > 40:
            # Not even converted: Python refuses to read an int of more than 4300 digits (and is slow below that).
            self.problems.append(Problem(self.doc.file, _pos(node.start_mark),
                                         f"{label}the number {_short(node.value)} is far too large{_range_of(path)}",
                                         _NUMBER_HINT))
            return None
        try:
            value = self.constructor.construct_object(node, deep=True)
        except yaml.YAMLError:
            raise
        except (ValueError, TypeError, OverflowError, KeyError, AttributeError) as exc:
            # An explicit tag whose text it cannot read (!!int 2 s, !!bool maybe, !!timestamp x, a date 2024-13-45).
            tag = node.tag.rsplit(":", 1)[-1]
            self.problems.append(Problem(self.doc.file, _pos(node.start_mark),
                                         f"{label}'{_short(node.value)}' cannot be read as {tag}"
                                         + (f": {exc}" if isinstance(exc, (ValueError, OverflowError)) else ""),
                                         "remove the '!!' tag, or put the text in quotes if it is text"))
            return None
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if isinstance(value, float) and not math.isfinite(value):
                self.problems.append(Problem(self.doc.file, _pos(node.start_mark),
                                             f"{label}'{_short(node.value)}' is not a finite number{_range_of(path)}",
                                             _NUMBER_HINT))
                return None
            if abs(value) > MAX_NUMBER:
                self.problems.append(Problem(self.doc.file, _pos(node.start_mark),
                                             f"{label}the number {_short(node.value)} is far too large"
                                             f"{_range_of(path)}", _NUMBER_HINT))
                return None
        return value


_DIGITS = re.compile(r"^[-+]?\d+$")
_DIGITS_AND_UNIT = re.compile(r"^\d+(\s*[^\s\d,:{}\[\]][^,:{}\[\]]*)?$")

_NUMBER_HINT = ("every number must be finite and within the range its field can mean (.nan, .inf and numbers "
                "beyond 1e15 mean nothing to a robot); write the value you mean, e.g. 'wait: 2 s', 'lat: 40.4168'")


def _range_of(path: PathKey) -> str:
    """``: 'lat' is a number from -90 to 90`` when the schemas say what the field's range is, else the rule for any
    number in a file."""
    from beastbt.core.field_ranges import field_range  # late: only a refused number needs the schemas
    key = next((part for part in reversed(path) if isinstance(part, str)), None)
    words = field_range(key) if key is not None else None
    if words:
        return f": '{key}' is {words}"
    return ": any number in a file is finite and at most 1e15 in size"


def _label(path: PathKey) -> str:
    """``'name': `` for the innermost key of ``path`` (how messages name the field), or nothing at the top."""
    for part in reversed(path):
        if isinstance(part, str):
            return f"'{part}': "
    return ""


def _short(text: str) -> str:
    """A scalar's text as a message quotes it: a long one cut, with its length."""
    text = text.strip()
    return text if len(text) <= 24 else f"{text[:12]}...{text[-4:]} ({len(text)} characters)"


class _CountingLoader(yaml.SafeLoader):
    """PyYAML's safe composer, remembering each alias's use (where it is written) and refusing an alias inside the
    anchor it refers to (``&a [*a]``, which would repeat forever)."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self.alias_uses: list[tuple[str, yaml.Mark, yaml.Node]] = []
        self._open: set[str] = set()

    def compose_node(self, parent: Any, index: Any) -> yaml.Node:  # noqa: D102 (PyYAML's hook)
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            if event.anchor in self._open:
                raise yaml.composer.ComposerError(
                    None, None, f"the alias *{event.anchor} is inside the anchor &{event.anchor} it refers to",
                    event.start_mark)
            node = super().compose_node(parent, index)
            self.alias_uses.append((event.anchor, event.start_mark, node))
            return node
        anchor = self.peek_event().anchor
        if anchor is None:
            return super().compose_node(parent, index)
        self._open.add(anchor)
        try:
            return super().compose_node(parent, index)
        finally:
            self._open.discard(anchor)


def _expanded_sizes(root: yaml.Node, cap: int) -> dict[int, int]:
    """How many values each node of the composed graph stands for with every alias expanded (each capped at
    ``cap``), by node id; computed once per distinct node, without expanding anything."""
    sizes: dict[int, int] = {}
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        if id(node) in sizes:
            continue
        if isinstance(node, yaml.SequenceNode):
            children = list(node.value)
        elif isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        else:
            sizes[id(node)] = 1
            continue
        if children_done:
            sizes[id(node)] = min(cap, 1 + sum(sizes[id(c)] for c in children))
        else:
            stack.append((node, True))
            stack.extend((c, False) for c in children if id(c) not in sizes)
    return sizes


def _alias_bomb(file: str, root: yaml.Node, uses: list[tuple[str, yaml.Mark, yaml.Node]]) -> Optional[Problem]:
    """A problem at the alias that takes the file beyond :data:`ALIAS_ALLOWANCE`, or None when it stays within."""
    if not uses:
        return None
    cap = 10 ** 12
    sizes = _expanded_sizes(root, cap)
    written = len(sizes)
    if sizes[id(root)] <= 2 * written + ALIAS_ALLOWANCE:
        return None
    # Point at the alias where the values added, in the order they are written, first pass the bound.
    added, where = 0, max(uses, key=lambda u: sizes[id(u[2])])
    for use in uses:
        added += sizes[id(use[2])]
        if added > ALIAS_ALLOWANCE + written:
            where = use
            break
    total = sizes[id(root)]
    amount = "more than a trillion" if total >= cap else f"{total:,}"
    return Problem(file, _pos(where[1]),
                   f"aliases expand this file to {amount} values ({written:,} written): more than a file may hold "
                   f"(an alias bomb?)",
                   f"aliases may add at most as many values as the file writes plus {ALIAS_ALLOWANCE:,}: do not nest "
                   f"aliases of aliases (in a mission, run repeated steps with 'repeat: {{times: N}}' or a task)")


class _TooDeep(Exception):
    """PyYAML's composer ran out of Python's recursion at ``mark`` (lists and mappings nested hundreds deep)."""

    def __init__(self, mark: yaml.Mark) -> None:
        super().__init__("nested too deeply")
        self.mark = mark


_FAST_REFUSED = re.compile(r"[*&!\\\t\ufeff\x85\u2028\u2029]|^%", re.MULTILINE)
"""What sends a document to PyYAML's own composer even when libyaml is there: aliases and anchors (counted and
bounded by :class:`_CountingLoader`), tags, escapes, tabs, a byte-order mark, Unicode line breaks, directives."""

_FAST_MAX_DEPTH = 200
"""libyaml composes a document only when it cannot nest deeper than this (brackets, plus the longest line for the
levels that indentation and '- ' can add): deeper ones go to PyYAML's composer, which says where it gave up."""


def _nests_within(text: str, depth: int) -> bool:
    """Whether libyaml's parser (iterative: it keeps its own stack) finds no list or mapping nested ``depth`` deep.

    The quick bound in :func:`_compose_fast` counts every bracket of the file, so a mission with a few hundred
    places written ``{lat: .., lon: ..}`` failed it and went to PyYAML's composer, ten times slower (issue 38:
    4,000 places took seconds). Counting the real nesting costs a parse without building nodes.
    """
    opened = 0
    try:
        for event in yaml.parse(text, Loader=yaml.CSafeLoader):
            if isinstance(event, yaml.CollectionStartEvent):
                opened += 1
                if opened >= depth:
                    return False
            elif isinstance(event, yaml.CollectionEndEvent):
                opened -= 1
    except Exception:  # noqa: BLE001 - whatever libyaml refuses, PyYAML's composer says why
        return False
    return True


def _compose_fast(text: str) -> Optional[yaml.Node]:
    """The node graph of a plain document composed by libyaml (PyYAML's C binding, some ten times faster than
    its Python composer: most of loading a mission or a profile), or None to compose it with :func:`_compose`.

    Only a document without anything in :data:`_FAST_REFUSED` or a character PyYAML refuses, that cannot nest
    beyond :data:`_FAST_MAX_DEPTH` and that libyaml reads without an error: every error, with its message and
    position, is PyYAML's own. The nodes are those PyYAML composes (a plain scalar's style is None, as there).
    """
    if not getattr(yaml, "__with_libyaml__", False) or _FAST_REFUSED.search(text) \
            or yaml.reader.Reader.NON_PRINTABLE.search(text):
        return None
    if text.count("[") + text.count("{") + max(map(len, text.splitlines()), default=0) >= _FAST_MAX_DEPTH \
            and not _nests_within(text, _FAST_MAX_DEPTH):
        return None
    try:
        root = yaml.compose(text, Loader=yaml.CSafeLoader)
    except Exception:  # noqa: BLE001 - whatever libyaml refuses, PyYAML's composer says why, as before
        return None
    if root is None:
        return None
    stack: list[yaml.Node] = [root]
    while stack:
        node = stack.pop()
        if isinstance(node, yaml.ScalarNode):
            if node.style == "":
                node.style = None  # libyaml marks a plain scalar '', PyYAML None (which _Builder reads)
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)
        elif isinstance(node, yaml.MappingNode):
            stack.extend(n for pair in node.value for n in pair)
    return root


def _compose(text: str) -> tuple[Optional[yaml.Node], list[tuple[str, yaml.Mark, yaml.Node]]]:
    """The document's node graph and its alias uses (``yaml.compose`` with :class:`_CountingLoader`, or libyaml's
    composer for a plain document: :func:`_compose_fast`)."""
    fast = _compose_fast(text)
    if fast is not None:
        return fast, []  # no '*' in it: no alias to count
    loader = _CountingLoader(text)
    try:
        return loader.get_single_node(), loader.alias_uses
    except RecursionError:
        raise _TooDeep(loader.get_mark()) from None
    except (ValueError, OverflowError) as exc:
        # The scanner's own slips (chr() of an escape beyond Unicode, '\U0011FFFF'): where the reader stopped.
        what = ("an escape that is no Unicode character (the largest is \\U0010FFFF)" if "chr()" in str(exc)
                else f"a value YAML cannot read ({exc})")
        raise yaml.scanner.ScannerError(None, None, what, loader.get_mark()) from None
    finally:
        loader.dispose()


def _missing_colon(lines: list[str], error_line: int) -> Optional[tuple[tuple[int, int], str]]:
    """The line above ``error_line`` (0-based) at its indentation that has no ':': ((line, column after its key), key)."""
    if not 0 <= error_line < len(lines):
        return None
    indent = len(lines[error_line]) - len(lines[error_line].lstrip())
    for i in range(error_line - 1, -1, -1):
        text = lines[i]
        if not text.strip() or text.lstrip().startswith("#"):
            continue
        if len(text) - len(text.lstrip()) != indent or ":" in text:
            return None
        word = text.strip().split()[0].lstrip("-").strip() or text.strip()
        return (i + 1, text.index(word) + len(word) + 1), word
    return None


def _reader_problem(file: str, text: str, exc: yaml.reader.ReaderError) -> Problem:
    """A character YAML does not allow (a control character, a NUL), at its line and column."""
    index = exc.position if isinstance(exc.position, int) and 0 <= exc.position <= len(text) else 0
    line = text.count("\n", 0, index) + 1
    column = index - (text.rfind("\n", 0, index) + 1) + 1
    char = exc.character
    code = f"#x{char:04x}" if isinstance(char, int) else repr(char)
    return Problem(file, Position(line, column), f"character {code} is not allowed in a YAML file ({exc.reason})",
                   "delete it (a control character or a NUL pasted by mistake?); a YAML file is printable text")


def _undecodable(file: str, exc: UnicodeDecodeError) -> Problem:
    """Bytes that are not UTF-8, at the line and column of the first of them."""
    data = exc.object if isinstance(exc.object, (bytes, bytearray)) else b""
    start = max(0, min(exc.start, len(data)))
    line = data.count(b"\n", 0, start) + 1
    line_start = data.rfind(b"\n", 0, start) + 1
    column = len(data[line_start:start].decode("utf-8", errors="replace")) + 1
    binary = data[:start].count(b"\0") > 0 or start == 0
    return Problem(file, Position(line, column),
                   "this is not a text file" if binary else f"byte 0x{data[start]:02x} here is not UTF-8 text",
                   "it must be a YAML text file (UTF-8); save it again as UTF-8 (a Latin-1 letter pasted in?)")


def _syntax_problem(file: str, text: str, exc: yaml.YAMLError) -> Problem:
    if isinstance(exc, yaml.reader.ReaderError):
        return _reader_problem(file, text, exc)
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    pos = _pos(mark) if mark is not None else Position(1, 1)
    problem = getattr(exc, "problem", None) or str(exc)
    lines = text.splitlines()
    line_text = lines[pos.line - 1] if 0 < pos.line <= len(lines) else ""
    if "\t" in line_text[: max(pos.column, 1)] or "'\\t'" in str(problem):
        col = line_text.find("\t") + 1 if "\t" in line_text else pos.column
        return Problem(file, Position(pos.line, max(col, 1)), "tab character used for indentation",
                       "YAML indentation must use spaces; replace the tab with spaces (2 per level is usual)")
    context = getattr(exc, "context", None)
    context_mark = getattr(exc, "context_mark", None)
    if str(problem).startswith("the alias *"):
        return Problem(file, pos, f"{problem}: it would repeat forever",
                       "an alias may only refer to an anchor that is complete before it; copy the part instead")
    if context == "while scanning a quoted scalar" and context_mark is not None:
        quote = lines[context_mark.line][context_mark.column] if context_mark.line < len(lines) else '"'
        return Problem(file, _pos(context_mark), f"this {quote} opens a text that is never closed",
                       f"end the text with {quote} on the same line (a text in quotes may not run past its line "
                       f"unless you mean it to)")
    if context in ("while parsing a flow mapping", "while parsing a flow sequence") and context_mark is not None:
        opener, closer = ("{", "}") if "mapping" in context else ("[", "]")
        line = context_mark.line
        end = len(lines[line].rstrip()) + 1 if line < len(lines) else 1
        if line < len(lines) and closer in lines[line][context_mark.column:]:
            return Problem(file, _pos(context_mark), f"the '{opener}...{closer}' here cannot be read",
                           "put quotes around any text in it that has ':', '?', '#', ',' or brackets, "
                           "e.g. question: \"Drive forward?\"")
        return Problem(file, Position(line + 1, end), f"the '{opener}' at line {line + 1} column "
                                                      f"{context_mark.column + 1} is never closed",
                       f"add '{closer}' at the end of line {line + 1}")
    if str(problem).startswith(("mapping values are not allowed here", "could not find expected ':'")):
        missing = _missing_colon(lines, pos.line - 1)
        if missing is not None:
            (line_no, column), word = missing
            return Problem(file, Position(line_no, column), f"missing ':' after '{word}'",
                           f"write '{word}: <value>' (a key, a colon and a space, then its value)")
    message = f"YAML syntax error: {problem}" + (f" ({context})" if context else "")
    return Problem(file, pos, message, "check the indentation and the ':' and '-' around this line; quote text that contains ': ' or '#'")


def _value_kind(value: Any) -> str:
    """What a value is, in words, without its content: ``text (40 characters)``, ``number``..."""
    if isinstance(value, str):
        return f"text ({len(value)} characters)"
    if isinstance(value, bool) or value is None:
        return f"value ({value!r})"
    return "number" if isinstance(value, (int, float)) else "value"


def load_yaml(path: Union[str, Path], text: str | None = None, display_name: str | None = None,
              require_mapping: bool = True) -> SourceDoc:
    """Read a YAML file into a :class:`SourceDoc`; raise :class:`InvalidInput` with every problem found.

    ``text`` may be given to parse a string instead of reading ``path``;
    ``display_name`` is how the file is named in messages (default: ``path``).
    """
    name = display_name or str(path)
    if text is None:
        from beastbt.core.file_refs import YAML_FILE, RefusedFile, read_capped
        try:
            # regular files only, at most YAML_MAX_BYTES: a device or a pipe named as a YAML file is not read
            text = read_capped(path, YAML_FILE, name).decode("utf-8")
        except RefusedFile as exc:
            if "does not exist" in exc.message:
                raise InvalidInput([Problem(name, Position(1, 1), "file not found",
                                            "check the path; relative paths are relative to the current "
                                            "directory")]) from None
            raise InvalidInput([Problem(name, Position(1, 1), exc.message, exc.hint)]) from None
        except UnicodeDecodeError as exc:
            raise InvalidInput([_undecodable(name, exc)]) from None
    doc = SourceDoc(file=name, data=None)
    try:
        node, alias_uses = _compose(text)
    except yaml.YAMLError as exc:
        raise InvalidInput([_syntax_problem(name, text, exc)])
    except _TooDeep as exc:
        raise InvalidInput([Problem(name, _pos(exc.mark), "nested too deeply for a YAML reader",
                                    f"keep lists and mappings within {MAX_NESTING} levels; move inner steps "
                                    f"into a task under 'tasks:' and run it with 'do: <task>'")]) from None
    if node is None:
        raise InvalidInput([Problem(name, Position(1, 1), "the file is empty",
                                    "a mission needs at least 'mission: <name>' and 'steps:'")])
    bomb = _alias_bomb(name, node, alias_uses)
    if bomb is not None:
        raise InvalidInput([bomb])
    builder = _Builder(doc, text)
    try:
        doc.data = builder.build(node, ())
    except yaml.YAMLError as exc:
        raise InvalidInput([_syntax_problem(name, text, exc)])
    if builder.problems:
        raise InvalidInput(builder.problems)
    if require_mapping and not isinstance(doc.data, dict):
        # the value is not quoted: a file named by mistake (/etc/passwd as a world) must not be shown in a message
        kind = "a list" if isinstance(doc.data, list) else f"a single {_value_kind(doc.data)}"
        raise InvalidInput([Problem(name, doc.position(()), f"the top level must be a mapping of keys, but it is {kind}",
                                    "start the file with 'mission: <name>' on its own line, with no '-' before it")])
    return doc
