"""How long the command line takes to answer before any computation: ``linkopt
--help`` and ``linkopt check`` of a broken file (the error a user sees first when a
file is wrong).

Run: ``.venv/bin/python benchmarks/bench_cli_startup.py [--repeat N]``.

Each case runs in a fresh process ``--repeat`` times (default 5) after one untimed run
that warms the file system and Python's bytecode cache; the median is compared with
``TARGET_S`` (issue 29: under 1 s warm, 2-core machine). Neither case imports JAX:
the command modules import the engine in their handlers, and ``check`` reads and
validates the file before anything is compiled (``tests/test_cli_startup.py`` checks
which modules are imported). The figures go to
``benchmarks/results/bench_cli_startup.json``.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _results

ROOT = Path(__file__).resolve().parent.parent
LINKOPT = [sys.executable, "-m", "linkopt"]
#: Seconds, warm, for either case (issue 29).
TARGET_S = 1.0
#: A mechanism file with one wrong field: a joint type linkopt does not know.
BROKEN = (
    (ROOT / "mechanisms" / "four_bar.toml")
    .read_text()
    .replace('type = "revolute"', 'type = "hinge"', 1)
)


def _seconds(command: list[str], expected: int) -> float:
    began = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    seconds = time.perf_counter() - began
    if done.returncode != expected:
        raise SystemExit(
            f"{' '.join(command)} exited {done.returncode}, expected {expected}:\n"
            f"{done.stderr}"
        )
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--out", default=str(_results.RESULTS))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        broken = Path(scratch) / "broken.toml"
        broken.write_text(BROKEN)
        cases = (
            ("linkopt --help", [*LINKOPT, "--help"], 0),
            ("linkopt check broken.toml", [*LINKOPT, "check", str(broken)], 2),
        )
        rows = []
        for label, command, expected in cases:
            _seconds(command, expected)  # untimed: warms caches
            times = [_seconds(command, expected) for _ in range(args.repeat)]
            median = statistics.median(times)
            verdict = "met" if median <= TARGET_S else "not met"
            print(f"{label:<28} {median:6.2f} s median of {len(times)}  "
                  f"(target {TARGET_S:.0f} s, {verdict})", flush=True)  # fmt: skip
            rows.append({"case": label, "seconds": times, "target": TARGET_S})
    _results.write(__file__, {"cases": rows}, args.out)


if __name__ == "__main__":
    main()
