"""Where a first run's time goes: every trace, lowering and XLA compilation of a
command, cold (empty caches) and warm.

Run: ``.venv/bin/python benchmarks/bench_compile.py [--workers 1] [-- COMMAND ...]``
(default command: ``optimize mechanisms/five_bar.toml``, the README's main job; an
``optimize`` or ``sweep`` command is given without ``--out``'s folder, which is a new
temporary one each pass).

Each pass runs the command in a fresh process with JAX's monitoring hooks on, first
with an empty compilation cache (``LINKOPT_CACHE_DIR`` a new temporary folder), then
again with the cache it filled, and prints the wall time, the seconds spent tracing,
lowering and compiling, and the programs by total compile time (a program compiled
for several argument shapes counts once per shape). ``--workers 1`` keeps every
compilation in the one process that is measured (with two, the spawned processes
compile too, in parallel, and are not counted).

Targets (issue 19, 2-core machine): the cold main command ≤ 60 s; the warm one ≤ 15 s.

Figures behind the choices (five-bar main command, ``--workers 1``, idle 2-core
machine, cold):

* before fixed blocks (:mod:`linkopt._engine.blocks`): 310 s wall, at least 204 s of
  it compiling (the 40 costliest programs: 75 compilations); ``_solve`` (warm-started
  FK/BK batches) compiled 9 times (82 s: one per padded wave size of each map and
  verification grid), ``_sigmas`` 6 times (19 s), ``_solve_path`` 4 times (21 s), the
  read-outs 20 times (5 s), the design evaluation 3 times (58 s with the partial
  gradient: the swarm's chunk, the gradient, and one design at the end).
* after (2026-12-03, ``--workers 2`` as the README's command): cold 178 s wall, 105 s
  compiling (64 compilations, 62 s of them the evaluation and its partial gradient,
  one ``_solve`` program each for FK and BK); warm 63 s (311 s and 77 s before).
* with the solves' traces on disk (:mod:`linkopt._engine.programs`) and σ_min's Jacobi
  rotations as row and column updates (2026-12-03, ``--workers 2``): cold 139.7 s
  wall, 89.3 s compiling (70 compilations: the evaluation 25.1 s, its partial
  gradient 23.8 s, the FK solves 11.2 s for one row and blocks of 64); warm 44.8 s,
  of it 0.0 s tracing (5.8 s before), 1.0 s lowering and 3.9 s loading executables
  from the cache. Warm-started batches of one row then went back to the block's
  program (the maps' first one-cell wave had compiled the one-row one too): cold
  145.3 s wall (run-to-run noise is about ±5 s), 87.1 s compiling, 67 compilations,
  FK 8.6 s and BK 5.6 s; warm 46.8 s.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TARGET_COLD = 60.0
TARGET_WARM = 15.0


def _child(command: list[str], report: Path) -> None:
    """Run ``linkopt COMMAND`` here with a listener on JAX's duration events and
    write what it recorded to ``report`` (JSON)."""
    from jax import monitoring

    began = time.perf_counter()
    records = []

    def listener(event, duration, **kwargs):
        records.append([event.rsplit("/", 1)[-1], kwargs.get("fun_name"), duration])

    monitoring.register_event_duration_secs_listener(listener)
    from linkopt._cli.main import main

    try:
        code = main(command)
    except SystemExit as stop:
        code = stop.code
    report.write_text(
        json.dumps(
            {"code": code, "wall": time.perf_counter() - began, "records": records}
        )
    )


def _pass(command: list[str], cache: Path) -> dict:
    with tempfile.TemporaryDirectory() as scratch:
        report = Path(scratch) / "report.json"
        env = {**os.environ, "LINKOPT_CACHE_DIR": str(cache)}
        subprocess.run(
            [sys.executable, __file__, "--child", str(report), "--", *command],
            env=env,
            cwd=ROOT,
            check=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        return json.loads(report.read_text())


def _summary(label: str, result: dict) -> None:
    totals = collections.defaultdict(float)
    programs = collections.defaultdict(lambda: [0, 0.0])
    for event, name, seconds in result["records"]:
        totals[event] += seconds
        if event == "backend_compile_duration":
            programs[name][0] += 1
            programs[name][1] += seconds
    compiled = sum(count for count, _ in programs.values())
    print(
        f"{label}: {result['wall']:.1f} s wall (exit {result['code']}); tracing "
        f"{totals['jaxpr_trace_duration']:.1f} s, lowering "
        f"{totals['jaxpr_to_mlir_module_duration']:.1f} s, compiling "
        f"{totals['backend_compile_duration']:.1f} s ({compiled} compilations), "
        f"cache retrieval {totals['cache_retrieval_time_sec']:.1f} s"
    )
    ranked = sorted(programs.items(), key=lambda item: -item[1][1])
    for name, (count, seconds) in ranked[:8]:
        print(f"    {seconds:7.1f} s  {count:3d} x  {name}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("command", nargs="*")
    args = parser.parse_args()
    if args.child is not None:
        _child(args.command, args.child)
        return
    with tempfile.TemporaryDirectory() as scratch:
        template = args.command or ["optimize", "mechanisms/five_bar.toml", "--out"]
        if template[0] in ("optimize", "sweep") and "--out" not in template:
            template = [*template, "--out"]
        passes = {}
        for label in ("cold", "warm"):  # a new run folder each, one cache for both
            command = [*template, "--workers", str(args.workers)]
            if command[0] in ("optimize", "sweep"):
                at = command.index("--out") + 1
                command.insert(at, str(Path(scratch) / label))
            passes[label] = _pass(command, Path(scratch) / "cache")
    cold, warm = passes["cold"], passes["warm"]
    print(f"linkopt {' '.join(command)}")
    _summary(f"cold (target <= {TARGET_COLD:.0f} s)", cold)
    _summary(f"warm (target <= {TARGET_WARM:.0f} s)", warm)


if __name__ == "__main__":
    main()
