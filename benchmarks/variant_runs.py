"""What the variant sweeps share (benchmarks/tight_gap_variants.py, benchmarks/people_variants.py): their command
line (``--seeds``, ``--jobs``, ``--only``) and running their jobs, one process or several."""

from __future__ import annotations

import argparse
from multiprocessing import Pool
from typing import Any, Callable, Sequence


def variant_arguments(description: str, every: str) -> tuple[argparse.Namespace, list[int], list[str]]:
    """The sweep's command line: (the arguments, the seeds, the variants named by ``--only``, empty for all);
    ``every`` says in ``--help`` what the default sweeps."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--seeds", default="1,2,3,4,5")
    ap.add_argument("--jobs", type=int, default=1, help="runs at once (processes)")
    ap.add_argument("--only", default="", help=f"variants, comma-separated (default: {every})")
    args = ap.parse_args()
    return args, [int(x) for x in args.seeds.split(",")], args.only.split(",") if args.only else []


def run_jobs(run: Callable[[Any], dict], jobs: Sequence[Any], processes: int) -> list[dict]:
    """``run`` of each job, in order: in ``processes`` worker processes when more than one (each job alone, so that
    a slow variant does not hold others back), else here."""
    if processes > 1:
        with Pool(processes) as pool:
            return pool.map(run, jobs, chunksize=1)
    return [run(j) for j in jobs]
