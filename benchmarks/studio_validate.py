"""How fast the studio answers the page as it is typed in: ``/api/validate``, ``/api/tree``, ``/api/map``,
``/api/edit``.

A studio is started on a free loopback port for the repository's folder, and
each request is timed from the client (HTTP on loopback included), after one
warm-up request, for the missions of missions/. Prints the median and the
worst of N requests per mission, and, as a baseline measured in the same run,
``GET /api/files/<mission>`` (a file read through the same server): the ratio
says what beastbt's checks cost over serving the text. Goal (issue 23): a
typo's problem at its line and column well within a second of typing; the page
asks 300 ms after the last key, so the answer should take well under 300 ms.

Run: python benchmarks/studio_validate.py [--repeats N]
"""

from __future__ import annotations

import argparse
import http.client
import json
import re
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.studio.server import StudioServer  # noqa: E402


def timed(port: int, method: str, path: str, body: object = None) -> tuple[float, dict]:
    """(seconds, JSON answer) of one request."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    data = None if body is None else json.dumps(body).encode()
    headers = {"Content-Type": "application/json"} if data is not None else {}
    t0 = time.perf_counter()
    conn.request(method, path, body=data, headers=headers)
    answer = json.loads(conn.getresponse().read())
    elapsed = time.perf_counter() - t0
    conn.close()
    return elapsed, answer


def main() -> int:
    """Print the timings; 0."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    server = StudioServer(REPO, "127.0.0.1", 0).start()
    medians: dict[str, list[float]] = {}
    worst: dict[str, float] = {}
    try:
        port = server.port
        print(f"{'mission':28} {'request':14} {'median ms':>10} {'worst ms':>9} {'x read':>7}")
        for mission in sorted((REPO / "missions").glob("*.yaml")):
            rel = mission.relative_to(REPO).as_posix()
            text = mission.read_text(encoding="utf-8")
            typo = text.replace("steps:", "stpes:", 1)
            requests = {
                "read (base)": ("GET", f"/api/files/{rel}", None),
                "validate": ("POST", "/api/validate", {"text": text, "path": rel}),
                "validate typo": ("POST", "/api/validate", {"text": typo, "path": rel}),
                "tree": ("POST", "/api/tree", {"text": text, "path": rel}),
                "map": ("POST", "/api/map", {"text": text, "path": rel}),
                "edit": ("POST", "/api/edit", {"text": text, "edit": {"op": "add_place", "lat": 40.4169,
                                                                      "lon": -3.7038}}),
            }
            times: dict[str, list[float]] = {name: [] for name in requests}
            for name, (method, path, body) in requests.items():
                timed(port, method, path, body)  # warm-up
            for _ in range(args.repeats):
                for name, (method, path, body) in requests.items():  # interleaved: the same load for all
                    times[name].append(timed(port, method, path, body)[0])
            base = statistics.median(times["read (base)"])
            for name, values in times.items():
                median = statistics.median(values)
                print(f"{mission.name:28} {name:14} {median * 1000:10.1f} {max(values) * 1000:9.1f} "
                      f"{median / base:7.1f}")
                medians.setdefault(name, []).append(median * 1000)
                worst[name] = max(worst.get(name, 0.0), max(values) * 1000)
    finally:
        server.close()
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("studio_validate")
    for name, values in medians.items():  # over the missions: the lowest and highest median, the worst request
        key = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
        figures.put(f"{key}.median_lowest_ms", min(values))
        figures.put(f"{key}.median_highest_ms", max(values))
        figures.put(f"{key}.worst_ms", worst[name])
    figures.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
