"""benchmarks/check_docs.py: the docs quote the benchmarks' last output (benchmarks/results/), within 30 %.

The repository's own README.md and docs/ pass against the committed results; on temporary copies, a quoted
figure too far off, an unknown key, a marker with no number and a measured figure without a marker fail, each
naming file:line:column, and goals, limits and settings pass without a marker.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import pytest

from conftest import REPO

SCRIPT = REPO / "benchmarks" / "check_docs.py"


def _load(name: str, path):
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


check_docs = _load("check_docs_under_test", SCRIPT)
figures = _load("figures_under_test", REPO / "benchmarks" / "figures.py")


@pytest.fixture
def results(tmp_path, monkeypatch):
    """A results folder with one benchmark, ``demo``, saved through benchmarks/figures.py: ``cpu_pct`` = 10."""
    folder = tmp_path / "results"
    monkeypatch.setenv("BEASTBT_FIGURES_DIR", str(folder))
    saved = figures.Figures("demo")
    saved.put("cpu_pct", 10.0)
    saved.spread("tick_us", [100.0, 90.0, 120.0])
    saved.save(out=open(tmp_path / "printed.txt", "w", encoding="utf-8"))
    return folder


def check(tmp_path, results, text: str) -> tuple[int, str]:
    doc = tmp_path / "doc.md"
    doc.write_text(text, encoding="utf-8")
    out = subprocess.run([sys.executable, str(SCRIPT), "--results", str(results), "--root", str(tmp_path), str(doc)],
                         capture_output=True, text=True, timeout=60)
    return out.returncode, out.stdout + out.stderr


def test_the_repository_docs_quote_the_committed_results():
    out = subprocess.run([sys.executable, str(SCRIPT)], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout[-3000:]
    checked = int(out.stdout.split("check_docs: ")[1].split()[0])
    assert checked >= 100, out.stdout[-500:]  # the docs do quote the benchmarks


def test_a_figure_31_percent_off_fails_naming_where_and_29_percent_passes(tmp_path, results):
    code, out = check(tmp_path, results, "# T\n\nIt takes 13.1<!--fig:demo.cpu_pct--> % of a core.\n")
    assert code == 1
    assert "doc.md:3:10: 13.1 quoted as demo.cpu_pct" in out and "last output is 10" in out
    command = json.loads((results / "demo.json").read_text(encoding="utf-8"))["runs"][0]["command"]
    assert f"re-run `{command}`" in out  # the command that measured it, to run again
    code, out = check(tmp_path, results, "# T\n\nIt takes 12.9<!--fig:demo.cpu_pct--> % of a core.\n")
    assert code == 0, out
    assert "1 figures checked" in out
    code, out = check(tmp_path, results, "# T\n\nIt takes 6.9<!--fig:demo.cpu_pct--> % of a core.\n")
    assert code == 1 and "31 % off" in out


def test_a_range_marks_both_ends(tmp_path, results):
    code, out = check(tmp_path, results, "A tick: 100<!--fig:demo.tick_us.median--> µs "
                                         "(90<!--fig:demo.tick_us.min-->-120<!--fig:demo.tick_us.max-->).\n")
    assert code == 0, out
    code, out = check(tmp_path, results, "A tick: 100<!--fig:demo.tick_us.median--> µs "
                                         "(90<!--fig:demo.tick_us.min-->-200<!--fig:demo.tick_us.max-->).\n")
    assert code == 1 and "doc.md:1:" in out and "200 quoted as demo.tick_us.max" in out


def test_an_unmarked_measured_figure_fails(tmp_path, results):
    code, out = check(tmp_path, results, "# T\n\nThe console costs 4.7 % of a core and a tick 2.5× the anchor.\n")
    assert code == 1
    assert "doc.md:3:19: 4.7 % has no marker" in out
    assert "doc.md:3:46: 2.5 × has no marker" in out


def test_a_number_under_a_unit_column_needs_a_marker(tmp_path, results):
    table = "| item | µs per call |\n|---|---:|\n| tree tick | 18.8 |\n"
    code, out = check(tmp_path, results, table)
    assert code == 1 and "doc.md:3:15: 18.8" in out
    code, out = check(tmp_path, results, table.replace("18.8", "100<!--fig:demo.tick_us.median-->"))
    assert code == 0, out


def test_an_unknown_key_a_missing_benchmark_and_a_marker_without_a_number_fail(tmp_path, results):
    code, out = check(tmp_path, results, "It takes 10<!--fig:demo.nope--> % of a core.\n")
    assert code == 1 and "doc.md:1:10:" in out and "demo saves no figure 'nope'" in out
    code, out = check(tmp_path, results, "It takes 10<!--fig:other.cpu_pct--> % of a core.\n")
    assert code == 1 and "no results file benchmarks/results/other.json" in out
    code, out = check(tmp_path, results, "It takes <!--fig:demo.cpu_pct--> a lot.\n")
    assert code == 1 and "doc.md:1:10:" in out and "no number right before it" in out


def test_goals_limits_settings_and_code_pass_unmarked(tmp_path, results):
    text = ("# Goals\n\nThe console: goal ≤ 5 % of a core.\n\n"
            "Recording adds at most +1 % of a core (the budget).\n\n"
            "A body of more than 4 kB is refused; `queue_max_items` 500 ms.\n\n"
            "| figure | goal |\n|---|---|\n| the console | 5 % |\n\n"
            "Run `beastbt run x.yaml --speed max` and read `2.5 % of a core`.\n\n"
            "```\nsteady 9.79 % of one core\n```\n\n"
            "The mission blinks 3 times; the map is 820 x 820 cells.\n")
    code, out = check(tmp_path, results, text)
    assert code == 0, out


def test_the_escape_needs_a_reason(tmp_path, results):
    code, out = check(tmp_path, results, "Noise: 0.5<!--nofig: the datasheet's figure--> % of the range.\n")
    assert code == 0, out
    code, out = check(tmp_path, results, "Noise: 0.5<!--nofig:--> % of the range.\n")
    assert code == 1 and "needs a reason" in out


def test_a_run_saves_its_figures_merged_with_the_parts_it_left_out(tmp_path, results, capsys):
    data = json.loads((results / "demo.json").read_text(encoding="utf-8"))
    assert data["figures"]["tick_us.median"]["value"] == 100.0
    assert data["figures"]["tick_us.min"]["value"] == 90.0
    assert data["runs"][0]["command"] and data["runs"][0]["machine"] and len(data["runs"][0]["load"]) == 3
    again = figures.Figures("demo")
    again.put("cpu_pct", 12.0)
    again.save()
    printed = capsys.readouterr().out
    assert "cpu_pct = 12" in printed  # a saved figure is printed
    data = json.loads((results / "demo.json").read_text(encoding="utf-8"))
    assert data["figures"]["cpu_pct"]["value"] == 12.0
    assert data["figures"]["tick_us.max"]["value"] == 120.0  # kept from the run that measured it
    assert len(data["runs"]) == 2
    assert data["figures"]["cpu_pct"]["run"] != data["figures"]["tick_us.max"]["run"]


def test_update_rewrites_only_figures_that_are_off_keeping_their_decimals(tmp_path, results):
    text = "A: 13.1<!--fig:demo.cpu_pct--> %, B: 95<!--fig:demo.tick_us.min--> µs, C: +20<!--fig:demo.cpu_pct--> %.\n"
    doc = tmp_path / "doc.md"
    doc.write_text(text, encoding="utf-8")
    out = subprocess.run([sys.executable, str(SCRIPT), "--update", "--results", str(results), "--root", str(tmp_path),
                          str(doc)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout
    assert doc.read_text(encoding="utf-8") == ("A: 10.0<!--fig:demo.cpu_pct--> %, B: 95<!--fig:demo.tick_us.min--> µs, "
                                               "C: +10<!--fig:demo.cpu_pct--> %.\n")
    assert "13.1 -> 10.0 (demo.cpu_pct)" in out.stdout and "+20 -> +10" in out.stdout
