"""End-to-end five-bar optimisation (paper Sec. VI-A, Table I): iterations, time, result.

Run: ``.venv/bin/python benchmarks/bench_optimizer.py [--seeds 0,1,2]``

For each seed, runs ``linkopt optimize`` in a fresh process (default settings: 20
particles, hybrid PSO + partial gradient) into a temporary directory and prints the
iterations, wall time (with compilation), final ``f_design`` and whether ``linkopt
verify`` passes on the result. Baseline: the paper's Table I, five-bar: 8 iterations,
about 15 min (C++, 4 cores).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FILE = ROOT / "mechanisms/five_bar.toml"
PAPER_ITERATIONS = 8
PAPER_SECONDS = 15 * 60


def run(seed: int) -> dict:
    with tempfile.TemporaryDirectory() as out:
        began = time.perf_counter()
        cmd = [sys.executable, "-m", "linkopt.cli", "optimize", str(FILE), "--out", out, "--seed", str(seed)]
        subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True, text=True)
        seconds = time.perf_counter() - began
        summary = json.loads((Path(out) / "summary.json").read_text())
    return {"seed": seed, "seconds": seconds, **{k: summary[k] for k in ("iterations", "f_design", "regularizer", "verified", "wall_time")}}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", default="0,1,2")
    args = parser.parse_args()
    print(f"five-bar optimisation; paper: {PAPER_ITERATIONS} iterations, {PAPER_SECONDS / 60:.0f} min")
    for seed in (int(s) for s in args.seeds.split(",")):
        r = run(seed)
        print(
            f"  seed {r['seed']}: {r['iterations']:3d} iterations, optimiser {r['wall_time']:6.1f} s,"
            f" whole command {r['seconds']:6.1f} s, f_design {r['f_design']:.2e},"
            f" regulariser {r['regularizer']:.2e}, verified {r['verified']}"
            f"  ({PAPER_SECONDS / r['seconds']:.1f}x faster than the paper)",
            flush=True,
        )


if __name__ == "__main__":
    main()
