"""Check that every measured figure quoted in README.md and docs/ is a benchmark's last output, within a tolerance.

A figure in the docs is bound to a benchmark's figure by a marker right after the number (no space between):
``1.2<!--fig:console.fake_mjpeg.console_pct.median--> % of a core``. The key is ``<benchmark>.<figure>``: the
figure is looked up in ``benchmarks/results/<benchmark>.json``, which the benchmark writes at the end of each run
(benchmarks/figures.py). A range marks both ends (``1.1<!--fig:....min-->..1.2<!--fig:....max-->``).

The check fails (exit 1) when:

- a quoted figure is more than ``--tolerance`` (default 30 %) off the benchmark's value, relative to it;
- a marker's key, or its benchmark's results file, does not exist, or a marker has no number right before it;
- a number with a unit of measurement (``%``, percentage points with decimals or a sign, µs, ms, s of CPU, a
  ratio such as ``2.1×``, ``31x`` or ``2.5 times``, MB, MiB, kB, GB, Mbit/s, fps, ``cm`` in a clause about an
  RMS error, or any number in a table column whose header names such a unit) has no marker, outside code spans
  and code blocks, unless its clause (between commas, semicolons, brackets, sentence ends or table bars) states
  a goal, a limit or a setting: goal, ≤, <, at most, at least, under or over a number, budget, limit, default,
  target, bound, timeout, period, resolution, debounce, a parameter's ``snake_case`` name in a code span; or
  its table column's header does. A figure that is not beastbt's measurement (a device's datasheet, a
  firmware's constant) takes ``<!--nofig: the reason-->`` right after the number instead, with a reason of at
  least two words.

Every failure names file:line:column, the quoted figure, the benchmark's value and the command that measured it.
``--update`` first rewrites each marked figure that is off to the saved value (as many decimals as it had);
the sentence around it (a goal met or missed) is still the reader's to check.

Run: python benchmarks/check_docs.py [--tolerance 0.3] [--results DIR] [--update] [FILE ...]
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).resolve().parent / "results"

NUM = r"(?:(?<![\w)>*])[+±−-])?\d+(?:,\d{3})*(?:\.\d+)?"
"""A quoted number: a sign only where it cannot be a range's dash (286-700 is two numbers, both positive)."""
MARKER = re.compile(r"<!--\s*(fig|nofig)\s*:\s*(.*?)\s*-->")
MARK = r"(?:<!--\s*(?:fig|nofig)\s*:.*?-->)?"
# A unit that says the number was measured (the test: would a person ask "which benchmark prints that?").
UNIT = (r"(?:%|points?\b|µs\b|us\b|ms\b|s of CPU\b|×(?!\s*\d)|x(?![\w\d])|times\b|MB\b|MiB\b|GB\b|kB\b|KiB\b"
        r"|Mbit/s|fps\b|cm\b)")
HEADER_UNIT = r"(?:%|µs\b|\bus\b|\bms\b|\bMiB\b|\bMB\b|\bkB\b|\bfps\b|Mbit/s|×)"
SEP = r"(?:\s*(?:-|–|to|\.\.|/|and)\s*)"
MEASURED = re.compile(rf"(?<![\w.#/-])({NUM}){MARK}(?:{SEP}({NUM}){MARK})?\**\s?\**({UNIT})")
NUMBER_BEFORE = re.compile(rf"({NUM})\**$")
ALLOW = re.compile(r"goal|≤|<|≥|>|\bat most\b|\bat least\b|\b(?:under|over|below|above|within|up to)\s+\**[~±]?\d"
                   r"|budget|\blimits?\b|\bdefaults?\b|\btargets?\b|\bbounds?\b|\baim|\basked\b|\bmore than\b"
                   r"|\bless than\b|\bdebounce|\btimeouts?\b|\bperiod\b|\bresolution\b|`-*[a-z]+_[a-z0-9_]+`",
                   re.IGNORECASE)
"""Words that make a clause a goal, a limit or a setting (its figures need no marker); the last: a parameter's
name in a code span (`max_speed_mps`)."""
RMS = re.compile(r"\bRMS\b")
CLAUSE_END = re.compile(r"[;()|]|\.\s|,\s|\.$")


@dataclass
class Failure:
    """One figure that does not hold, with where it is."""

    where: str
    message: str

    def __str__(self) -> str:
        return f"{self.where}: {self.message}"


def parse_number(text: str) -> float:
    """A quoted number as a float: thousands separators dropped, a Unicode minus or ± read as a sign."""
    return float(text.replace(",", "").replace("−", "-").replace("±", ""))


def mask_code(lines: list[str]) -> list[str]:
    """The lines with fenced code blocks and inline code spans blanked out (same columns, spaces)."""
    out, fence = [], None
    for line in lines:
        stripped = line.lstrip()
        if fence is None and (stripped.startswith("```") or stripped.startswith("~~~")):
            fence = stripped[:3]
            out.append(" " * len(line))
            continue
        if fence is not None:
            if stripped.startswith(fence):
                fence = None
            out.append(" " * len(line))
            continue
        out.append(re.sub(r"(`+)(.+?)\1", lambda m: " " * len(m.group(0)), line))
    return out


def load_results(folder: Path) -> dict[str, Optional[dict]]:
    """Every results file in ``folder`` by benchmark name (None for one that does not parse)."""
    found: dict[str, Optional[dict]] = {}
    for path in sorted(folder.glob("*.json")):
        try:
            found[path.stem] = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            found[path.stem] = None
    return found


def lookup(key: str, results: dict[str, Optional[dict]]) -> tuple[Optional[float], str, str]:
    """(value, command that measured it, error) for ``<benchmark>.<figure>``."""
    bench, _, figure = key.partition(".")
    rerun = f"python benchmarks/{bench}.py"
    if bench not in results:
        return None, rerun, f"no results file benchmarks/results/{bench}.json (run {rerun})"
    data = results[bench]
    if data is None:
        return None, rerun, f"benchmarks/results/{bench}.json does not parse (run {rerun} again)"
    fig = data.get("figures", {}).get(figure)
    if fig is None:
        known = ", ".join(sorted(data.get("figures", {}))[:8])
        return None, rerun, (f"{bench} saves no figure {figure!r} (some it saves: {known}); hint: check the key, "
                             f"or make {rerun} print and save it")
    try:
        runs = data.get("runs", [])
        run = runs[fig["run"]] if 0 <= fig.get("run", -1) < len(runs) else {}
        return float(fig["value"]), str(run.get("command", rerun)), ""
    except (AttributeError, KeyError, TypeError, ValueError):
        return None, rerun, f"benchmarks/results/{bench}.json: figure {figure!r} is not a number (run {rerun} again)"


def clause(text: str, start: int, end: int) -> str:
    """The clause around text[start:end]: from the last ; ( ) | , or sentence end before it to the next after it,
    markers blanked out."""
    text = MARKER.sub(lambda m: " " * len(m.group(0)), text)
    left = max((m.end() for m in CLAUSE_END.finditer(text, 0, start)), default=0)
    right_m = CLAUSE_END.search(text, end)
    return text[left: right_m.start() if right_m else len(text)]


def check_file(path: Path, results: dict[str, Optional[dict]], tolerance: float,
               shown: Optional[str] = None) -> tuple[int, list[Failure]]:
    """(figures checked, failures) for one Markdown file."""
    name = shown or str(path)
    raw = path.read_text(encoding="utf-8").splitlines()
    lines = mask_code(raw)
    checked, failures = 0, []
    for lineno, (line, original) in enumerate(zip(lines, raw), start=1):
        # Markers: each binds the number right before it.
        for m in MARKER.finditer(line):
            col = m.start() + 1
            kind, body = m.group(1), m.group(2)
            before = NUMBER_BEFORE.search(line[:m.start()])
            where = f"{name}:{lineno}:{col}"
            if before is None:
                failures.append(Failure(where, f"the marker <!--{kind}:{body}--> has no number right before it; "
                                               f"hint: put it right after the figure, no space between"))
                continue
            if kind == "nofig":
                if len(body.split()) < 2:
                    failures.append(Failure(where, "<!--nofig: ...--> needs a reason (why this is not a measurement "
                                                   "of beastbt's), at least two words"))
                continue
            checked += 1
            quoted_text = before.group(1)
            quoted = parse_number(quoted_text)
            fig_col = before.start(1) + 1
            where = f"{name}:{lineno}:{fig_col}"
            if not re.fullmatch(r"[a-z0-9_]+(\.[a-z0-9_]+)+", body):
                failures.append(Failure(where, f"marker key {body!r}: expected <benchmark>.<figure>, lower-case words "
                                               f"joined by dots"))
                continue
            value, command, error = lookup(body, results)
            if value is None:
                failures.append(Failure(where, f"{quoted_text} quoted as {body}: {error}"))
                continue
            off = abs(quoted - value) / abs(value) if value != 0 else (0.0 if quoted == 0 else float("inf"))
            if off > tolerance:
                failures.append(Failure(where, f"{quoted_text} quoted as {body}, but the benchmark's last output is "
                                               f"{value:g} ({off * 100:.0f} % off, more than {tolerance * 100:.0f} %); "
                                               f"hint: re-run `{command}` and quote what it prints"))
    failures += unmarked(name, lines, raw)
    return checked, failures


def _blocks(lines: list[str]) -> list[list[int]]:
    """Line indexes grouped as the clauses run: a paragraph's lines together, each table row alone."""
    blocks: list[list[int]] = []
    current: list[int] = []
    for i, line in enumerate(lines):
        if not line.strip() or line.lstrip().startswith(("|", "#")):
            if current:
                blocks.append(current)
            current = []
            if line.strip():
                blocks.append([i])
            continue
        if line.lstrip().startswith(("- ", "* ", "+ ")) or re.match(r"\s*\d+\. ", line):
            if current:
                blocks.append(current)
            current = []
        current.append(i)
    if current:
        blocks.append(current)
    return blocks


def _cells(line: str) -> list[tuple[int, int]]:
    """(start, end) of each cell of a Markdown table row, the pipes left out."""
    bars = [m.start() for m in re.finditer(r"(?<!\\)\|", line)]
    return [(a + 1, b) for a, b in zip(bars, bars[1:])]


def _table_units(lines: list[str]) -> dict[int, dict[int, bool]]:
    """For each table body row (line index): its columns whose header names a unit, and whether the header states
    a goal or limit (then its figures need no marker)."""
    found: dict[int, dict[int, bool]] = {}
    i = 0
    while i + 1 < len(lines):
        head, sep = lines[i], lines[i + 1]
        if head.lstrip().startswith("|") and re.fullmatch(r"\s*\|[\s:|-]+\|?\s*", sep) and "-" in sep:
            columns = {}
            for c, (a, b) in enumerate(_cells(head)):
                text = head[a:b]
                if ALLOW.search(text):
                    columns[c] = True
                elif re.search(HEADER_UNIT, text):
                    columns[c] = False
            j = i + 2
            while j < len(lines) and lines[j].lstrip().startswith("|"):
                if columns:
                    found[j] = columns
                j += 1
            i = j
        else:
            i += 1
    return found


def unmarked(name: str, lines: list[str], raw: list[str]) -> list[Failure]:
    """Failures for measured figures without a marker: a number with a unit, or in a column whose header has one."""
    failures = []
    table = _table_units(lines)

    def fail(i: int, col: int, number: str, unit: str) -> None:
        failures.append(Failure(
            f"{name}:{i + 1}:{col + 1}",
            f"{number} {unit} has no marker: a measured figure must name the benchmark figure it quotes; hint: write "
            f"{number}<!--fig:BENCHMARK.KEY--> (a goal or limit says so in its clause: goal, ≤, at most; not "
            f"beastbt's measurement: <!--nofig: reason-->)"))

    for block in _blocks(lines):
        starts, text, text_raw = [], "", ""
        for i in block:
            starts.append(len(text))
            text += lines[i] + "\n"
            text_raw += raw[i] + "\n"

        def place(offset: int) -> tuple[int, int]:
            k = max(n for n, s0 in enumerate(starts) if s0 <= offset)
            return block[k], offset - starts[k]

        seen: set[int] = set()
        for m in MEASURED.finditer(text):
            unit = m.group(3)
            around = clause(text, m.start(), m.end())
            if unit == "cm" and not RMS.search(around):
                continue  # a length is a setting or a size unless it is an error's RMS
            if unit == "times" and "." not in (m.group(2) or m.group(1)):
                continue  # "3 times": a count; a measured ratio has decimals (2.5 times)
            if unit == "x" and text[m.end() - 2].isspace() and "." not in (m.group(2) or m.group(1)):
                continue  # "4 x 4", "9 x 25 arcs": a size; a ratio is written 31x or 2.5 x
            if unit.startswith("point") and not re.search(r"[.+±−-]", (m.group(2) or m.group(1))):
                continue  # points of a scan (450 points per scan); percentage points have decimals or a sign
            if unit == "ms" and re.match(r"\s*(reads?|steps?|windows?|ticks?)\b", text[m.end():]):
                continue  # a duration used as a size: 10 ms reads, 50 ms steps
            for group in (1, 2):
                if m.group(group) is not None:
                    seen.add(m.start(group))
            if ALLOW.search(clause(text_raw, m.start(), m.end())) or ALLOW.search(around):
                continue
            if len(block) == 1 and block[0] in table and any(
                    table[block[0]].get(c) and a <= m.start() < b for c, (a, b) in enumerate(_cells(lines[block[0]]))):
                continue  # under a goal column's header
            for group in (1, 2):
                if m.group(group) is None or MARKER.match(text[m.end(group):]):
                    continue
                i, col = place(m.start(group))
                fail(i, col, m.group(group), unit)
        # Numbers under a header that names their unit (| µs |).
        if len(block) == 1 and block[0] in table:
            i = block[0]
            line = lines[i]
            for c, (a, b) in enumerate(_cells(line)):
                if c not in table[i] or table[i][c]:
                    continue  # no unit in the header, or a goal column
                cell = line[a:b]
                if ALLOW.search(clause(raw[i], a, a)) or ALLOW.search(cell):
                    continue
                for n in re.finditer(rf"(?<![\w.#/-]){NUM}", cell):
                    if a + n.start() in seen or MARKER.match(cell[n.end():]):
                        continue
                    fail(i, a + n.start(), n.group(0), "(the column's unit)")
    return failures


QUOTED = re.compile(rf"({NUM})(\**)(<!--\s*fig\s*:\s*([a-z0-9_.]+)\s*-->)")


def update_file(path: Path, results: dict[str, Optional[dict]], tolerance: float) -> list[str]:
    """Rewrite the marked figures of ``path`` that are more than ``tolerance`` off to their saved value, with as
    many decimals as the quoted figure had; the changes made, one line each. The prose around a figure (a goal
    met or not) is the reader's to check."""
    text = path.read_text(encoding="utf-8")
    changes: list[str] = []

    def quote(m: re.Match) -> str:
        value, _, _ = lookup(m.group(4), results)
        quoted = m.group(1)
        if value is None:
            return m.group(0)
        old = parse_number(quoted)
        if (abs(old - value) / abs(value) if value != 0 else abs(old)) <= tolerance:
            return m.group(0)
        decimals = len(quoted.split(".")[1]) if "." in quoted else 0
        sign = "+" if quoted.startswith("+") and value >= 0 else ""
        new = f"{sign}{value:{',' if ',' in quoted else ''}.{decimals}f}"
        line = text.count("\n", 0, m.start()) + 1
        changes.append(f"{path}:{line}: {quoted} -> {new} ({m.group(4)})")
        return new + m.group(2) + m.group(3)

    updated = QUOTED.sub(quote, text)
    if updated != text:
        path.write_text(updated, encoding="utf-8")
    return changes


def doc_files(root: Path) -> list[Path]:
    """README.md and every Markdown file under docs/."""
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def main(argv: Optional[list[str]] = None) -> int:
    """Check the files; print every failure and a summary; 0 when all hold, 1 otherwise."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("files", nargs="*", help="Markdown files (default README.md and docs/**/*.md)")
    ap.add_argument("--tolerance", type=float, default=0.30, help="relative difference allowed (default 0.30)")
    ap.add_argument("--results", default=str(RESULTS), help="folder of results files (default benchmarks/results)")
    ap.add_argument("--root", default=str(REPO), help="repository root (default this one)")
    ap.add_argument("--update", action="store_true",
                    help="first rewrite each marked figure that is off to the benchmark's value (then read the "
                         "sentence around it: a goal met or missed is not rewritten)")
    args = ap.parse_args(argv)
    root = Path(args.root)
    files = [Path(f) for f in args.files] or doc_files(root)
    results = load_results(Path(args.results))
    if args.update:
        for path in files:
            if path.exists():
                for change in update_file(path, results, args.tolerance):
                    print(f"updated {change}")
    total, failures = 0, []
    for path in files:
        if not path.exists():
            failures.append(Failure(str(path), "no such file"))
            continue
        try:
            shown = str(path.resolve().relative_to(root.resolve()))
        except ValueError:
            shown = str(path)
        checked, failed = check_file(path, results, args.tolerance, shown)
        total += checked
        failures += failed
    for failure in failures:
        print(failure)
    off = sum(1 for f in failures if "off, more than" in f.message)
    print(f"check_docs: {total} figures checked in {len(files)} files, {off} off by more than "
          f"{args.tolerance * 100:.0f} %, {len(failures)} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
