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

Targets (issue 19, 2-core machine): ``TARGET_COLD`` seconds for the cold main command,
``TARGET_WARM`` for the warm one. The figures go to
``benchmarks/results/bench_compile.json``. The choices they led to are documented where
they are made: one program per batch size (:mod:`linkopt._engine.blocks`), traces kept
on disk (:mod:`linkopt._engine.programs`), the XLA options (:mod:`linkopt._config`).
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

import _results

ROOT = Path(__file__).resolve().parent.parent
#: Seconds for the main command from an empty cache, and with the cache it filled
#: (issue 19, 2-core machine).
TARGET_COLD = 60.0
TARGET_WARM = 15.0
#: Programs listed per pass, by total compile time.
TOP_PROGRAMS = 8


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


def _summary(label: str, result: dict) -> dict:
    """Print a pass's totals and its costliest programs; return them as a record."""
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
    for name, (count, seconds) in ranked[:TOP_PROGRAMS]:
        print(f"    {seconds:7.1f} s  {count:3d} x  {name}")
    return {
        "wall_s": result["wall"],
        "exit": result["code"],
        "tracing_s": totals["jaxpr_trace_duration"],
        "lowering_s": totals["jaxpr_to_mlir_module_duration"],
        "compiling_s": totals["backend_compile_duration"],
        "compilations": compiled,
        "cache_retrieval_s": totals["cache_retrieval_time_sec"],
        "programs": [
            {"program": name, "compile_s": seconds, "compilations": count}
            for name, (count, seconds) in ranked[:TOP_PROGRAMS]
        ],
    }


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
            command = list(template)
            if command[0] in ("optimize", "sweep"):
                command += ["--workers", str(args.workers)]
                at = command.index("--out") + 1
                command.insert(at, str(Path(scratch) / label))
            passes[label] = _pass(command, Path(scratch) / "cache")
    cold, warm = passes["cold"], passes["warm"]
    print(f"linkopt {' '.join(command)}")
    shown = ["DIR" if part.startswith(scratch) else part for part in command]
    figures = {"command": "linkopt " + " ".join(shown), "passes": []}
    for label, result, target in (
        ("cold", cold, TARGET_COLD),
        ("warm", warm, TARGET_WARM),
    ):
        record = _summary(f"{label} (target <= {target:.0f} s)", result)
        programs = record.pop("programs")
        figures["passes"].append({"pass": label, "target_s": target, **record})
        figures[f"{label}_programs"] = programs
    _results.write(__file__, figures)


if __name__ == "__main__":
    main()
