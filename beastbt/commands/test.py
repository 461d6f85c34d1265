"""``beastbt test [PATH ...]``: run every mission test file (``*.test.yaml``) on its seeds, in parallel, and say how each did.

Every file x seed is one run at full speed on the simulator, recorded under
``runs/`` unless ``--no-record``; the runs are shared among ``-j N``
processes (default: the machine's cores). One line per test file with its
seeds' results and the first failure in words, then a total.

Exit status: 0 every run passed, 1 some run failed, 2 a test file is invalid
(its problems as ``FILE:LINE:COLUMN: error: ...`` on standard error) or no
test file was found, 130 interrupted (Ctrl-C or SIGTERM). ``--junit FILE`` writes JUnit XML for CI: one test case
per file x seed, a failing one with its failures as the message.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any, Optional, Sequence

EXIT_SUCCESS, EXIT_FAILURE, EXIT_INVALID = 0, 1, 2
EXIT_INTERRUPTED = 130
"""Ctrl-C or SIGTERM: the run under way stops as any run does (recorded, robot stopped), and no other starts."""


def _jobs(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number of processes") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"'{text}': give 1 or more processes")
    return value


def _seeds(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number of seeds") from None
    if not 1 <= value <= 1000:
        raise argparse.ArgumentTypeError(f"'{text}': give 1 to 1000 seeds")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``beastbt test``."""
    p.add_argument("paths", nargs="*", default=["."], metavar="PATH",
                   help="test files, or folders to search for *.test.yaml (default: the current folder)")
    p.add_argument("-j", "--jobs", type=_jobs, default=None, metavar="N",
                   help="runs at once, each in a process of its own (default: the number of cores)")
    p.add_argument("--seeds", type=_seeds, metavar="N", help="run seeds 1..N of every test instead of its seeds:")
    p.add_argument("--junit", metavar="FILE", help="also write the results as JUnit XML to FILE (for CI)")
    p.add_argument("--runs-dir", default="runs", help="where run folders go (default: ./runs)")
    p.add_argument("--no-record", action="store_true", help="do not write run folders")


def default_jobs() -> int:
    """The number of cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _run_job(job: tuple[str, Optional[int], int, bool, str]) -> Any:
    """One file x seed in a worker: the test loaded again there (cheap), run, its result returned."""
    from beastbt.testing.runs import run_seed
    from beastbt.testing.spec import load_test
    path, seeds, seed, record, runs_dir = job
    try:
        return run_seed(load_test(path, seeds), seed, record=record, runs_dir=runs_dir)
    except KeyboardInterrupt:
        import multiprocessing
        if multiprocessing.parent_process() is not None:
            os._exit(EXIT_INTERRUPTED)  # a worker told to stop: its run is stopped and kept; it takes no other
        raise


def run_all(jobs: list[tuple[str, Optional[int], int, bool, str]], processes: int, done: Any) -> list[Any]:
    """Run every job (in ``processes`` worker processes when more than one), calling ``done(index, result)`` as
    each finishes; the results in the jobs' order."""
    results: list[Any] = [None] * len(jobs)
    if processes <= 1 or len(jobs) <= 1:
        # SIGTERM ends the session from the start, not only once a run's loop has its own handler: before
        # that (a run being prepared, its folder already made) it would kill the process without a word
        restore = _sigterm_as_interrupt()
        try:
            for i, job in enumerate(jobs):
                results[i] = _run_job(job)
                done(i, results[i])
        finally:
            restore()
        return results
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    # fork where there is one: the workers start with beastbt already imported, in milliseconds
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else None
    pool = ProcessPoolExecutor(max_workers=min(processes, len(jobs)), mp_context=multiprocessing.get_context(method))
    restore = _sigterm_as_interrupt()
    try:
        futures = {pool.submit(_run_job, job): i for i, job in enumerate(jobs)}
        for future in as_completed(futures):
            i = futures[future]
            results[i] = future.result()
            done(i, results[i])
    except KeyboardInterrupt:
        # The workers' runs stop as a run stops on SIGTERM (recorded, the robot stopped); none starts after.
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            process.terminate()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    finally:
        restore()
    pool.shutdown()
    return results


def _sigterm_as_interrupt() -> Any:
    """SIGTERM raises KeyboardInterrupt in this (main) thread until the returned function puts the handler back."""
    import signal
    import threading
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt("SIGTERM")
    previous = signal.signal(signal.SIGTERM, interrupt)
    return lambda: signal.signal(signal.SIGTERM, previous)


def test_line(label: str, name: str, results: list[Any]) -> str:
    """One test file's line: PASS/FAIL, the file and its name, each seed's result, the first failure."""
    passed = sum(r.passed for r in results)
    seeds = ", ".join(f"{r.seed} {'ok' if r.passed else 'FAIL'}" for r in results)
    line = f"{'PASS' if passed == len(results) else 'FAIL'}  {label}: {name} ({passed}/{len(results)} seeds: {seeds})"
    first = next((r for r in results if not r.passed), None)
    if first is not None:
        line += f" -- {first.first_failure()}"
    return line


def write_junit(path: str, tests: list[tuple[Any, list[Any]]], elapsed_s: float,
                invalid: Sequence[tuple[str, str]] = ()) -> None:
    """JUnit XML: one testsuite per test file, one testcase per seed, a failing one with its failures; an invalid
    file (``invalid``: its path and its problems) is a testsuite with one testcase in error."""
    import xml.etree.ElementTree as ET
    total = sum(len(rs) for _, rs in tests) + len(invalid)
    failed = sum(1 for _, rs in tests for r in rs if r.failures and r.error is None)
    errors = sum(1 for _, rs in tests for r in rs if r.error is not None) + len(invalid)
    root = ET.Element("testsuites", name="beastbt test", tests=str(total), failures=str(failed), errors=str(errors),
                      time=f"{elapsed_s:.3f}")
    for test, results in tests:
        suite = ET.SubElement(root, "testsuite", name=str(test.file), tests=str(len(results)),
                              failures=str(sum(1 for r in results if r.failures and r.error is None)),
                              errors=str(sum(1 for r in results if r.error is not None)),
                              time=f"{sum(r.wall_s for r in results):.3f}")
        classname = str(test.file).removesuffix(".yaml").replace(os.sep, ".").strip(".")
        for r in results:
            case = ET.SubElement(suite, "testcase", classname=classname, name=f"{test.name} [seed {r.seed}]",
                                 time=f"{r.wall_s:.3f}")
            if r.error is not None:
                ET.SubElement(case, "error", message=r.first_failure(), type="run").text = r.message()
            elif r.failures:
                ET.SubElement(case, "failure", message=r.first_failure(), type="expectation").text = r.message()
            if r.folder:
                ET.SubElement(case, "system-out").text = f"run folder: {r.folder}"
    for file, problems in invalid:
        suite = ET.SubElement(root, "testsuite", name=file, tests="1", failures="0", errors="1", time="0.000")
        case = ET.SubElement(suite, "testcase", classname=file.removesuffix(".yaml").replace(os.sep, ".").strip("."),
                             name="invalid test file", time="0.000")
        ET.SubElement(case, "error", message=problems.splitlines()[0], type="invalid").text = problems
    tree = ET.ElementTree(root)
    ET.indent(tree)
    tree.write(path, encoding="utf-8", xml_declaration=True)


def command(args: argparse.Namespace) -> int:
    """Find, check and run the tests; print a line per test and a total. 0 all passed, 1 some failed, 2 invalid."""
    from beastbt.commands.paths import output_file_problem, output_folder_problem
    from beastbt.core.errors import InvalidInput
    from beastbt.testing.spec import SUFFIX, find_tests, load_test
    for problem in (output_file_problem("--junit", args.junit),
                    None if args.no_record else output_folder_problem("--runs-dir", args.runs_dir)):
        if problem is not None:
            print(f"beastbt test: error: {problem}", file=sys.stderr)
            return EXIT_INVALID
    files = find_tests(args.paths)
    if not files:
        print(f"beastbt test: error: no *{SUFFIX} file under {', '.join(args.paths)}", file=sys.stderr)
        return EXIT_INVALID
    started = time.monotonic()
    tests, invalid = [], []
    for f in files:
        try:
            tests.append(load_test(f, args.seeds))
        except InvalidInput as exc:
            print(exc.format(), file=sys.stderr)
            invalid.append((str(f), exc.format()))
    jobs = [(str(t.file), args.seeds, seed, not args.no_record, args.runs_dir) for t in tests for seed in t.seeds]
    spans, start = [], 0
    for t in tests:
        spans.append((start, start + len(t.seeds)))
        start += len(t.seeds)
    finished: dict[int, Any] = {}
    printed = [0]

    def done(i: int, result: Any) -> None:
        # Each test's line as soon as its seeds are done and the tests before it are printed: file order.
        finished[i] = result
        while printed[0] < len(tests) and all(j in finished for j in range(*spans[printed[0]])):
            k = printed[0]
            print(test_line(str(tests[k].file), tests[k].name, [finished[j] for j in range(*spans[k])]), flush=True)
            printed[0] += 1

    try:
        results = run_all(jobs, args.jobs or default_jobs(), done) if jobs else []
    except KeyboardInterrupt:
        print(f"beastbt test: interrupted after {len(finished)} of {len(jobs)} runs", file=sys.stderr)
        return EXIT_INTERRUPTED
    by_test = [(t, results[a:b]) for t, (a, b) in zip(tests, spans)]
    elapsed = time.monotonic() - started
    runs_passed = sum(r.passed for r in results)
    tests_passed = sum(all(r.passed for r in rs) for _, rs in by_test)
    total = (f"{len(tests)} test{'s' if len(tests) != 1 else ''}: {tests_passed} passed, "
             f"{len(tests) - tests_passed} failed ({runs_passed}/{len(results)} seeds passed) in {elapsed:.1f} s")
    if invalid:
        total += f"; {len(invalid)} invalid test file{'s' if len(invalid) != 1 else ''} (not run)"
    print(total)
    if args.junit:
        write_junit(args.junit, by_test, elapsed, invalid)
    if invalid or any(r.invalid for r in results):
        return EXIT_INVALID
    return EXIT_SUCCESS if runs_passed == len(results) else EXIT_FAILURE


__all__ = ["add_arguments", "command", "write_junit", "run_all", "default_jobs"]
