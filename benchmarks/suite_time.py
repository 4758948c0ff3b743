"""The test suite's cost, file by file, from an empty cache: CPU seconds per test file.

Run: ``.venv/bin/python benchmarks/suite_time.py [--label after] tests/test_a.py ...``

Each file runs alone, in one process (``pytest -q -n 0``), with linkopt's caches and
JAX's compilation cache in a fresh empty folder (``$LINKOPT_CACHE_DIR``), so every
program it needs is traced and compiled as in a cold CI run. The figure is the CPU time
of the process and its children (user + system, from ``os.wait4``), which stays
comparable on a machine shared with other work where wall time does not; the wall time
is recorded beside it. A record per (file, label) is kept in
``benchmarks/results/suite_time.json``; running a file again under the same label
replaces its record, so ``--label before`` on one commit and ``--label after`` on
another give the before/after table of a speed-up.
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
RESULTS = _results.RESULTS / "suite_time.json"


def measure(
    test_file: str, select: str | None, workers: str = "0", warm: str | None = None
) -> dict:
    """One cold run of ``test_file`` (several, space-separated; ``-k select`` where
    given; ``workers``: pytest-xdist's ``-n`` and, after a colon, its ``--dist``, e.g.
    ``2:worksteal``; ``warm``: a command run first in the same cache folder, not timed,
    e.g. the tests that in the suite run before it): CPU and wall seconds, the summary
    line, the exit status."""
    with tempfile.TemporaryDirectory(prefix="linkopt-suite-time-") as cache:
        env = {**os.environ, "LINKOPT_CACHE_DIR": cache}
        if warm:
            subprocess.run(warm, shell=True, cwd=ROOT, env=env, capture_output=True)
        count, _, dist = workers.partition(":")
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"]
        cmd += ["-n", count] + (["--dist", dist] if dist else [])
        cmd += test_file.split() + (["-k", select] if select else [])
        began = time.perf_counter()
        proc = subprocess.Popen(
            cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
        )
        out = proc.stdout.read().decode(errors="replace")
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - began
    lines = [line for line in out.splitlines() if line.strip()]
    return {
        "file": test_file
        + (f" -k {select}" if select else "")
        + (f" -n {workers}" if workers != "0" else "")
        + (f" after {warm!r}" if warm else ""),
        "cpu_s": round(usage.ru_utime + usage.ru_stime, 1),
        "user_s": round(usage.ru_utime, 1),
        "sys_s": round(usage.ru_stime, 1),
        "wall_s": round(wall, 1),
        "result": lines[-1].strip("= ") if lines else "",
        "exit": os.waitstatus_to_exitcode(status),
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("files", nargs="+", help="test files, e.g. tests/test_x.py")
    parser.add_argument("--label", default="now", help="e.g. before, after")
    parser.add_argument("-k", dest="select", default=None, help="pytest -k expression")
    parser.add_argument("-n", dest="workers", default="0", help="e.g. 2:worksteal")
    parser.add_argument("--warm", default=None, help="command run first, untimed")
    parser.add_argument("--results", default=str(RESULTS), help="the records' file")
    args = parser.parse_args()
    results = Path(args.results)
    kept = json.loads(results.read_text()) if results.exists() else {}
    old = kept.get("files", [])
    note = {k: v for k, v in kept.items() if k == "conditions"}  # kept where written
    for test_file in args.files:
        record = {
            "label": args.label,
            **measure(test_file, args.select, args.workers, args.warm),
        }
        print(
            f"{record['label']:>8} {record['file']:55} cpu {record['cpu_s']:7.1f} s"
            f"  wall {record['wall_s']:7.1f} s  {record['result']}",
            flush=True,
        )
        old = [
            r
            for r in old
            if (r["label"], r["file"]) != (record["label"], record["file"])
        ]
        old.append(record)
        _results.write(
            results.name,
            {**note, "files": sorted(old, key=lambda r: r["file"])},
            results.parent,
        )


if __name__ == "__main__":
    main()
