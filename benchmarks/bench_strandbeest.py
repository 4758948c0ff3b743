"""A strandbeest (one crank driving ``2k`` Jansen legs, ``tests/strandbeest.py``): FK
time per solve against the legs on the arrowhead factor
(:mod:`linkopt._engine.arrowhead`, the ground and crank last) and on the dense one
(what the default took before: the hubs make the plain band as wide as the
mechanism), the load-time checks, and the CLI on ``mechanisms/strandbeest_12.toml``:
``check``, ``evaluate`` and a short ``optimize``, each timed with its peak memory.

Run: ``.venv/bin/python benchmarks/bench_strandbeest.py [--legs 4,8,12,24,48]
[--dense-max 12] [--rows 8] [--repeats 3] [--no-cli] [--no-fk]
[--commands check,evaluate,optimize]``

The FK rows are crank angles uniform within ±``SPAN`` rad of rest, seed 0, solved from
the rest pose (continuation, then Levenberg–Marquardt); dense and arrowhead are timed
alternately after one compiling call each (the median of ``--repeats`` kept) and their
states compared. The optimisation is ``--iterations 2 --particles 4 --workers 1
--verify-rounds 0 --resolution 10`` (a smoke run: the cost of an iteration and of the
outputs, not a design). Writes ``benchmarks/results/bench_strandbeest.json`` (FK and
loading) and ``bench_strandbeest_cli.json`` (the commands).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _results
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

import strandbeest  # noqa: E402

SPAN = 0.3
FILE = ROOT / "mechanisms" / "strandbeest_12.toml"
OPTIMIZE = [
    "--iterations", "2", "--particles", "4", "--workers", "1",
    "--verify-rounds", "0", "--resolution", "10",
]  # fmt: skip


def _mechanism(legs: int, factor: str):
    from linkopt._files.fields import parse_toml
    from linkopt._files.loader import build

    mech = build(parse_toml(strandbeest.strandbeest(legs), "sb"), "sb", check=False)
    return dataclasses.replace(
        mech, solver=dataclasses.replace(mech.solver, factor=factor)
    )


def _timed(run) -> float:
    start = time.perf_counter()
    run()
    return time.perf_counter() - start


def measure(legs: int, rows: int, repeats: int, dense: bool) -> dict:
    import jax

    from linkopt import motor_values
    from linkopt._engine.geometry import rest_state
    from linkopt._engine.kinematics import solve_batch_from_rest

    factors = ("dense", "banded") if dense else ("banded",)
    mechs = {f: _mechanism(legs, f) for f in factors}
    mech = mechs["banded"]
    rest = np.asarray(rest_state(mech))
    motors = motor_values(mech, rest) + np.random.default_rng(0).uniform(
        -SPAN, SPAN, size=(rows, mech.num_motors)
    )

    def solver(m):
        return lambda: jax.block_until_ready(
            solve_batch_from_rest(m, "fk", motors, None)
        )

    runs = {f: solver(m) for f, m in mechs.items()}
    first = {f: _timed(run) for f, run in runs.items()}
    times = {f: [] for f in factors}
    for _ in range(repeats):
        for f in factors:
            times[f].append(_timed(runs[f]) / rows)
    answers = {f: runs[f]() for f in factors}
    record = {
        "legs": legs,
        "bodies": mech.num_bodies,
        "rows": rows,
        "converged": float(np.mean(np.asarray(answers["banded"].converged))),
        "iterations": float(np.mean(np.asarray(answers["banded"].iterations))),
        "arrowhead_s": statistics.median(times["banded"]),
        "arrowhead_first_call_s": first["banded"],
    }
    if dense:
        record["dense_s"] = statistics.median(times["dense"])
        record["dense_first_call_s"] = first["dense"]
        record["ratio"] = record["dense_s"] / record["arrowhead_s"]
        gap = np.asarray(answers["dense"].state) - np.asarray(answers["banded"].state)
        record["max_state_difference"] = float(np.max(np.abs(gap)))
    return record


def slope(records: list[dict], key: str) -> float | None:
    pts = [(r["bodies"], r[key]) for r in records if key in r]
    if len(pts) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def load_times() -> dict:
    """``linkopt.load`` of the 12-leg file with its checks (mobility and σ_min at
    rest, on the dense Jacobians) against the build alone."""
    import linkopt
    from linkopt._files.fields import parse_toml
    from linkopt._files.loader import build

    text = FILE.read_text()
    linkopt.load(FILE)  # warm: imports, compiled programs
    checked = _timed(lambda: linkopt.load(FILE))
    bare = _timed(lambda: build(parse_toml(text, "sb"), "sb", check=False))
    return {"load_with_checks_s": checked, "build_without_checks_s": bare}


def cli(command: list[str]) -> dict:
    """Wall time and peak memory of one ``linkopt`` command (``/usr/bin/time``)."""
    exe = Path(sys.executable).with_name("linkopt")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run(
        ["/usr/bin/time", "-f", "RSS %M", str(exe), *command],
        capture_output=True, text=True, env=env, check=False,
    )  # fmt: skip
    rss = re.findall(r"RSS (\d+)", done.stderr)
    return {
        "command": "linkopt " + " ".join(command),
        "returncode": done.returncode,
        "peak_rss_mb": int(rss[-1]) / 1024 if rss else None,
        "last_line": (done.stdout.strip().splitlines() or [""])[-1][:200],
    }


def timed_cli(command: list[str]) -> dict:
    start = time.perf_counter()
    record = cli(command)
    record["wall_s"] = time.perf_counter() - start
    return record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--legs", default="4,8,12,24,48")
    parser.add_argument("--dense-max", type=int, default=12)
    parser.add_argument("--rows", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-cli", action="store_true")
    parser.add_argument("--no-fk", action="store_true")
    parser.add_argument("--commands", default="check,evaluate,optimize")
    args = parser.parse_args()
    if not args.no_fk:
        fk_and_load(args)
    if not args.no_cli:
        commands = args.commands.split(",")
        _results.write("bench_strandbeest_cli", {"cli": cli_runs(commands)})


def fk_and_load(args) -> None:
    records = []
    for legs in (int(s) for s in args.legs.split(",")):
        rec = measure(legs, args.rows, args.repeats, legs <= args.dense_max)
        records.append(rec)
        line = f"{legs:3d} legs, {rec['bodies']:4d} bodies: arrowhead "
        line += f"{rec['arrowhead_s'] * 1e3:8.2f} ms/solve ({rec['iterations']:.1f} it)"
        if "dense_s" in rec:
            line += f", dense {rec['dense_s'] * 1e3:8.2f} ms/solve "
            line += f"(x{rec['ratio']:.2f}, |Δs| {rec['max_state_difference']:.1e})"
        print(line, flush=True)
    slopes = {
        "arrowhead": slope(records, "arrowhead_s"),
        "dense": slope(records, "dense_s"),
    }
    print(f"log-log slope of time per solve against bodies: {slopes}", flush=True)
    loads = load_times()
    print(f"load: {loads}", flush=True)
    _results.write(
        "bench_strandbeest", {"fk_per_solve": records, "slope": slopes, "load": loads}
    )


def cli_runs(commands: list[str]) -> list[dict]:
    records = []
    with tempfile.TemporaryDirectory() as tmp:
        runs = [
            ["check", str(FILE)],
            ["evaluate", str(FILE)],
            ["optimize", str(FILE), "--out", f"{tmp}/run", *OPTIMIZE],
        ]
        for command in (r for r in runs if r[0] in commands):
            record = timed_cli(command)
            records.append(record)
            print(
                f"{record['command'][:60]}: {record['wall_s']:.1f} s, "
                f"{record['peak_rss_mb']:.0f} MB, rc {record['returncode']}",
                flush=True,
            )
    return records


if __name__ == "__main__":
    main()
