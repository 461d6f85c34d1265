"""How fast the studio gets out of a large text's way: a check ended at its time limit, a worker replaced, and a
busy studio ended by SIGTERM (issue 38: "SIGTERM ends a busy studio in under 2 s").

``beastbt studio`` runs as a user starts it, on an empty folder. Each round:
one try runs, both workers check a text that takes minutes (150,000 waits) and
a third request waits for them; then SIGTERM, timed until the process has
exited. Separately, against a studio with a 1 s limit: how long the too-large
answer takes (the limit, plus killing), and how long until a fresh worker
answers a small text. Prints the median and the worst.

Run: python benchmarks/studio_bounds.py [--rounds N]
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

SMALL = "mission: m\nsteps:\n  - wait: 1 s\n"
BIG = "mission: many\nsteps:\n" + "  - wait: 1 s\n" * 150_000


def post(port: int, path: str, body: dict, timeout_s: float = 120) -> tuple[int, dict]:
    """(status, JSON answer) of one request."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=timeout_s)
    conn.request("POST", path, json.dumps(body), {"Content-Type": "application/json"})
    answer = conn.getresponse()
    status, data = answer.status, json.loads(answer.read())
    conn.close()
    return status, data


def send_only(port: int, path: str, body: dict) -> socket.socket:
    """Send a request and leave its answer unread (the socket stays open)."""
    data = json.dumps(body).encode()
    sock = socket.create_connection(("127.0.0.1", port), timeout=30)
    sock.sendall(f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json\r\n"
                 f"Content-Length: {len(data)}\r\n\r\n".encode() + data)
    return sock


def sigterm_round(folder: Path) -> float:
    """Seconds from SIGTERM to the exit of a studio busy with a try and two long checks."""
    env = dict(os.environ, PYTHONPATH=str(REPO), TMPDIR=str(folder))
    proc = subprocess.Popen([sys.executable, "-m", "beastbt", "studio", str(folder), "--listen", "127.0.0.1:0"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
    assert proc.stdout is not None
    url = [proc.stdout.readline() for _ in range(2)][1].split()[-1]
    port = int(url.rsplit(":", 1)[1].strip("/"))
    post(port, "/api/validate", {"text": SMALL})
    post(port, "/api/try", {"text": "mission: long\nsteps:\n  - wait: 300 s\n", "speed": "realtime"})
    socks = [send_only(port, "/api/validate", {"text": BIG}) for _ in range(3)]
    time.sleep(3.0)
    start = time.perf_counter()
    proc.send_signal(signal.SIGTERM)
    proc.wait(60)
    took = time.perf_counter() - start
    for sock in socks:
        sock.close()
    return took


def main() -> int:
    """Print the timings; 0."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    from beastbt.studio.server import StudioServer
    ended, replaced, sigterm = [], [], []
    with tempfile.TemporaryDirectory(prefix="beastbt-bench-studio-") as tmp:
        server = StudioServer(tmp, "127.0.0.1", 0, work_timeout_s=1.0).start()
        try:
            post(server.port, "/api/validate", {"text": SMALL})
            for _ in range(args.rounds):
                time.sleep(3.0)  # both workers warm again
                start = time.perf_counter()
                status, answer = post(server.port, "/api/validate", {"text": BIG})
                ended.append(time.perf_counter() - start)
                assert "too large" in answer["problems"][0]["message"], answer
                start = time.perf_counter()
                post(server.port, "/api/validate", {"text": SMALL})  # the other worker, warm
                post(server.port, "/api/validate", {"text": SMALL})
                while len(server.pool.pids()) < 2:
                    time.sleep(0.02)
                replaced.append(time.perf_counter() - start)
        finally:
            server.close()
        for _ in range(args.rounds):
            sigterm.append(sigterm_round(Path(tmp)))
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("studio_bounds")
    for name, values in (("too_large_answer_at_1s_limit_s", ended), ("worker_replaced_s", replaced),
                         ("sigterm_busy_exit_s", sigterm)):
        print(f"{name:32} median {statistics.median(values):6.2f} s  worst {max(values):6.2f} s")
        figures.put(f"{name}.median", statistics.median(values))
        figures.put(f"{name}.worst", max(values))
    figures.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
