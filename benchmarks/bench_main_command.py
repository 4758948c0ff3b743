"""The main command end to end, before and after a change (issue 43: "whole main
command warm <= 8 s, cold <= 25 s"): ``linkopt optimize mechanisms/five_bar.toml
--seed 0 --out DIR`` run by two checkouts in turn, each with its own cache folder.

Run: ``.venv/bin/python benchmarks/bench_main_command.py --before TREE [--after TREE]
[--repeat N] [--cold]`` (``--after``: this checkout). Each run is a fresh process of
``TREE``'s code (``PYTHONPATH=TREE``), warm: its cache folder filled by an untimed
first run of the same tree (``--cold``: that first run is timed as the cold one). The
runs alternate before/after, so a machine whose load changes affects both alike.

Each run is split by its progress lines' arrival: **start** (process start to the
first iteration's line less that iteration's own time), **optimiser** (its last
iteration line's ``elapsed``, the figure the issue quotes), **round** (from the last
iteration's line to the ``writing the optimised file ...`` line: the verification
round(s); the command line's side process makes the file's design's outputs meanwhile)
and **outputs** (from that line to the process's exit: the verification, the
optimised file, MJCF, figures, GIFs and ``view.html``). Also CPU seconds (the process
and its children). The medians over the repeats and their after/before ratios are
printed and written to ``benchmarks/results/bench_main_command.json``; every run's
``summary.json`` must give the same iterations and ``verified``; ``f_design`` must be
bitwise equal within a tree and, between the trees, equal within :data:`F_DESIGN_RTOL`
relative or :data:`F_DESIGN_ATOL` absolute (a change of the arithmetic's order moves
the main job's f_design, itself about 1e-21, by about 1e-6 of itself).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _results

ROOT = Path(__file__).resolve().parent.parent
FILE = "mechanisms/five_bar.toml"
WRITING = "writing the optimised file"
#: Tolerance of f_design between the two trees (module docstring).
F_DESIGN_RTOL = 1e-5
F_DESIGN_ATOL = 1e-15
ELAPSED = re.compile(r"^iteration .*elapsed\s+([0-9.]+) s")


def _children_cpu() -> float:
    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    return used.ru_utime + used.ru_stime


def run_once(tree: Path, cache: Path, out: Path) -> dict:
    """One ``optimize`` of ``tree``'s code: the phases' seconds and its summary."""
    env = {**os.environ, "PYTHONPATH": str(tree), "LINKOPT_CACHE_DIR": str(cache)}
    command = [sys.executable, "-m", "linkopt._cli.main", "optimize", FILE]
    command += ["--seed", "0", "--out", str(out)]
    cpu, began = _children_cpu(), time.perf_counter()
    proc = subprocess.Popen(
        command,
        cwd=tree,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    first_line = writing = last_line = None
    elapsed = []
    for line in proc.stderr:
        now = time.perf_counter() - began
        match = ELAPSED.match(line)
        if match:
            elapsed.append(float(match[1]))
            last_line = now
            if first_line is None:
                first_line = now
        elif line.startswith(WRITING):
            writing = now
    stdout = proc.stdout.read()
    if proc.wait() != 0:
        raise SystemExit(f"{tree}: optimize exited {proc.returncode}")
    whole = time.perf_counter() - began
    summary = json.loads((out / "summary.json").read_text())
    assert json.loads(stdout)["iterations"] == summary["iterations"]
    return {
        "whole_s": whole,
        "start_s": first_line - elapsed[0],
        "optimiser_s": elapsed[-1],
        "round_s": writing - last_line,
        "outputs_s": whole - writing,
        "cpu_s": _children_cpu() - cpu,
        "iterations": summary["iterations"],
        "f_design": summary["f_design"],
        "verified": summary["verified"],
    }


def _median(runs: list[dict], key: str) -> float:
    return statistics.median(r[key] for r in runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, required=True)
    parser.add_argument("--after", type=Path, default=ROOT)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cold", action="store_true")
    args = parser.parse_args()
    trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    cold: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="bench_main_") as tmp:
        tmp = Path(tmp)
        for name, tree in trees.items():  # fill each tree's cache
            result = run_once(tree, tmp / f"cache_{name}", tmp / f"{name}_cold")
            cold[name] = result
            print(f"{name:<6} cold  " + _line(result), flush=True)
        for i in range(args.repeat):
            for name, tree in trees.items():
                result = run_once(tree, tmp / f"cache_{name}", tmp / f"{name}_{i}")
                runs[name].append(result)
                print(f"{name:<6} warm  " + _line(result), flush=True)
    keys = ("whole_s", "start_s", "optimiser_s", "round_s", "outputs_s", "cpu_s")
    medians = {n: {k: _median(r, k) for k in keys} for n, r in runs.items()}
    print(
        f"\nmedians of {args.repeat} warm runs (load at start {_results.LOAD_AT_START})"
    )
    for key in keys:
        b, a = medians["before"][key], medians["after"][key]
        print(f"  {key:<12} before {b:6.2f}  after {a:6.2f}  ratio {a / b:5.2f}")
    _check_results(runs, cold)
    _results.write(
        __file__,
        {
            "file": FILE,
            "trees": {n: str(t) for n, t in trees.items()},
            "warm_median": medians,
            "warm_runs": runs,
            "cold": cold if args.cold else None,
            "result": {
                n: {k: rs[0][k] for k in ("iterations", "f_design", "verified")}
                for n, rs in runs.items()
            },
        },
    )


def _check_results(runs: dict[str, list[dict]], cold: dict[str, dict]) -> None:
    """Every run of a tree gives that tree's result bitwise; the trees agree on the
    iterations and ``verified``, and on ``f_design`` within the stated tolerance."""
    by_tree = {n: [cold[n], *rs] for n, rs in runs.items()}
    first = {}
    for name, results in by_tree.items():
        kinds = {(r["iterations"], r["f_design"], r["verified"]) for r in results}
        assert len(kinds) == 1, f"{name}: runs of one tree differ: {kinds}"
        first[name] = results[0]
    before, after = first["before"], first["after"]
    for key in ("iterations", "verified"):
        assert before[key] == after[key], f"{key}: {before[key]} != {after[key]}"
    assert math.isclose(
        before["f_design"], after["f_design"], rel_tol=F_DESIGN_RTOL,
        abs_tol=F_DESIGN_ATOL,
    ), f"f_design: {before['f_design']!r} != {after['f_design']!r}"  # fmt: skip


def _line(r: dict) -> str:
    return (
        f"whole {r['whole_s']:6.2f} s  start {r['start_s']:5.2f}  optimiser "
        f"{r['optimiser_s']:5.2f}  round {r['round_s']:5.2f}  outputs "
        f"{r['outputs_s']:5.2f}  CPU {r['cpu_s']:6.1f}"
        f"  ({r['iterations']} it, f_design {r['f_design']!r}, verified "
        f"{r['verified']})"
    )


if __name__ == "__main__":
    main()
