"""benchmarks/pi_factor.py runs (a --quick smoke run), prints its score and compares two machines' JSON."""

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_pi_factor_quick_prints_score_and_factor(tmp_path):
    """The quick run prints every item and a score; --compare against a machine twice as slow gives x2.00."""
    mine = tmp_path / "mine.json"
    out = subprocess.run([sys.executable, "benchmarks/pi_factor.py", "--quick", "--json", str(mine)], cwd=REPO,
                         capture_output=True, text=True, timeout=60, check=True).stdout
    data = json.loads(mine.read_text())
    assert set(data["items"]) == {"tree", "ekf", "raycast", "json", "video"}
    assert f"score: {data['score_us']:.1f}" in out
    slow = dict(data, machine="slow", score_us=data["score_us"] * 2,
                items={k: {"median_us": v["median_us"] * 2} for k, v in data["items"].items()})
    other = tmp_path / "slow.json"
    other.write_text(json.dumps(slow))
    out = subprocess.run([sys.executable, "benchmarks/pi_factor.py", "--quick", "--compare", str(other)], cwd=REPO,
                         capture_output=True, text=True, timeout=60, check=True).stdout
    factor = float(out.rsplit("factor: x", 1)[1].split()[0])
    assert 1.0 < factor < 4.0, out   # twice the other machine's own figures, against a fresh run here (noisy)
