"""Replays of runs that use the camera's words: each recorded on the simulator, then replayed; differences counted.

For each seed: missions/dock.yaml on worlds/lab.yaml (dock from 3 m and 40 deg off, wait, undock) and, with
``--route``, a campus route with ``at_each: [photo, look, wait]`` (about 330 simulated seconds a seed). Each run
is recorded as ``beastbt run`` records it, then replayed (``beastbt replay``): prints the ticks, the ticks whose
commands differ (goal: 0), both outcomes, how many recorded detector answers were given back and how many the
replay had to compute again (goal: 0 for the recorded mission), and the size of ``/vision/answers`` against
the whole file.

Run: python benchmarks/replay_camera.py [--seeds 1-5] [--route]
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.assembly import prepare  # noqa: E402
from beastbt.recording.reader import read_recording  # noqa: E402
from beastbt.replay import replay  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402
from figures import Figures  # noqa: E402  (benchmarks/figures.py, beside this script)

ROUTE = """mission: at_each
world: {world}
places:
  a: {{lat: 40.41690, lon: -3.70380}}
  b: {{lat: 40.41700, lon: -3.70350, tolerance: 3 m}}
  c: {{lat: 40.41680, lon: -3.70330}}
steps:
  - route: {{places: [a, b, c], at_each: [photo, {{look: {{pan: -45 deg}}}}, {{wait: 2 s}}, {{look: {{pan: 0 deg}}}}]}}
"""


def seeds(text: str) -> list[int]:
    """``1-5`` or ``1,3`` as a list of seeds."""
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


def one(mission: Path, world: str, seed: int, runs: Path) -> dict:
    """Record ``mission`` on ``world`` with ``seed``, replay it; what the replay found."""
    p = prepare(str(mission), RunOptions(simulate=True, seed=seed, world=world, runs_dir=str(runs)))
    summary = execute(p, io.StringIO())
    assert p.folder is not None
    mcap = Path(p.folder.path) / "run.mcap"
    rec = read_recording(mcap)
    answers = rec.topic("/vision/answers")
    result = replay(str(p.folder.path))
    given = next((n for n in result.notes if "recorded answers" in n), "")
    return {"ticks": result.ticks, "differing": result.differing_ticks, "recorded": result.recorded_status,
            "replayed": result.replay_status, "answers": len(answers), "given": given.split(" recorded")[0].split()[-1]
            if given else "0", "computed": sum(1 for n in result.notes if "computed again" in n),
            "answers_kb": sum(len(json.dumps(m)) for m in answers) / 1000, "file_kb": mcap.stat().st_size / 1000,
            "status": summary["status"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-5", help="seeds, e.g. 1-5 or 1,3 (default 1-5)")
    ap.add_argument("--route", action="store_true", help="also the campus route with at_each (slow)")
    args = ap.parse_args()
    figures = Figures("replay_camera")
    with tempfile.TemporaryDirectory() as tmp:
        cases = [("dock", REPO / "missions" / "dock.yaml", str(REPO / "worlds" / "lab.yaml"))]
        if args.route:
            route = Path(tmp) / "route.yaml"
            route.write_text(ROUTE.format(world=REPO / "worlds" / "campus.yaml"), encoding="utf-8")
            cases.append(("route", route, str(REPO / "worlds" / "campus.yaml")))
        for name, mission, world in cases:
            differing = 0
            for seed in seeds(args.seeds):
                r = one(mission, world, seed, Path(tmp) / "runs")
                differing += r["differing"]
                print(f"{name} seed {seed}: {r['ticks']} ticks, {r['differing']} differing; recorded {r['recorded']}, "
                      f"replay {r['replayed']}; {r['answers']} answers recorded, {r['given']} given back, "
                      f"{r['computed']} notes of answers computed again; /vision/answers {r['answers_kb']:.1f} kB "
                      f"of JSON, the file {r['file_kb']:.0f} kB", flush=True)
            figures.put(f"{name}.differing_ticks", differing)
    figures.save()


if __name__ == "__main__":
    main()
