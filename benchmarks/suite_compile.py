"""Per test, cold: how much of its time is tracing and XLA compiling, and which ones.

Run: ``.venv/bin/python benchmarks/suite_compile.py [--label now] tests/test_a.py ...``

Each file runs alone, in one process (``pytest -q -n 0``), with a fresh empty
``$LINKOPT_CACHE_DIR`` and ``$LINKOPT_COMPILE_STATS`` set, so the plugin in
``tests/_compile_stats.py`` records every test's CPU and wall seconds, its compile,
trace and lowering seconds, its number of compilations and disk-cache hits, and the
programs it spent most compile time on. A test that compiles much with few cache hits
compiles programs no earlier test shared (another sample count, grid, swarm size,
mechanism or option): the candidates to move onto the shapes the rest already compile.
The records go to ``benchmarks/results/suite_compile.json`` (a file's records under a
label replace that file's earlier ones), slowest CPU first, with each file's totals.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _results

ROOT = Path(__file__).resolve().parent.parent
RESULTS = _results.RESULTS / "suite_compile.json"


def measure(test_file: str) -> tuple[list[dict], dict]:
    """The per-test records and the file's totals of one cold run of ``test_file``."""
    with tempfile.TemporaryDirectory(prefix="linkopt-suite-compile-") as cache:
        stats = Path(cache) / "stats.jsonl"
        env = {
            **os.environ,
            "LINKOPT_CACHE_DIR": str(Path(cache) / "cache"),
            "LINKOPT_COMPILE_STATS": str(stats),
        }
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n0"]
        began = time.perf_counter()
        proc = subprocess.Popen(
            cmd + [test_file],
            cwd=ROOT,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
        )
        out = proc.stdout.read().decode(errors="replace")
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - began
        records = (
            [json.loads(line) for line in stats.read_text().splitlines()]
            if stats.exists()
            else []
        )
    lines = [line for line in out.splitlines() if line.strip()]
    total = {
        "file": test_file,
        "cpu_s": round(usage.ru_utime + usage.ru_stime, 1),
        "wall_s": round(wall, 1),
        "compile_s": round(sum(r["compile_s"] for r in records), 1),
        "compiles": sum(r["compiles"] for r in records),
        "trace_s": round(sum(r["trace_s"] for r in records), 1),
        "result": lines[-1].strip("= ") if lines else "",
        "exit": os.waitstatus_to_exitcode(status),
    }
    return records, total


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("files", nargs="+", help="test files, e.g. tests/test_x.py")
    parser.add_argument("--label", default="now", help="e.g. before, after")
    args = parser.parse_args()
    for test_file in args.files:
        records, total = measure(test_file)
        print(json.dumps(total), flush=True)
        tests = [{"label": args.label, "file": test_file, **r} for r in records]
        _merge({"label": args.label, **total}, tests)


def _merge(total: dict, tests: list[dict]) -> None:
    """Write one file's totals and test records into the results, replacing that
    (label, file)'s earlier ones; the file is read just before it is written, so runs
    in parallel keep each other's records."""
    key = (total["label"], total["file"])
    kept = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    files = [r for r in kept.get("files", []) if (r["label"], r["file"]) != key]
    old = [r for r in kept.get("tests", []) if (r["label"], r["file"]) != key]
    _results.write(
        RESULTS,
        {
            "conditions": "each file alone in one process (pytest -n 0), fresh "
            "LINKOPT_CACHE_DIR, tests/_compile_stats.py on; cpu_s of a test is its "
            "process's CPU (XLA's threads included, subprocesses not)",
            "files": sorted(files + [total], key=lambda r: -r["cpu_s"]),
            "tests": sorted(old + tests, key=lambda r: -r["cpu_s"]),
        },
    )


if __name__ == "__main__":
    main()
