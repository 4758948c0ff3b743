"""How big each stored program of a command is, and which linkopt functions its
operations come from: what a cold start traces and compiles.

Run: ``.venv/bin/python benchmarks/program_size.py [--top N] [--no-compile] -- COMMAND``
(default command: ``evaluate mechanisms/stewart.toml --json``).

The command runs in this process with an empty cache folder. Every program that
:func:`linkopt._engine.programs.call` traces is also traced with ``jax.make_jaxpr``
(its equations counted through every nested jaxpr: a jitted function called at two
sites counts twice, as XLA inlines it twice), lowered to StableHLO and compiled with
linkopt's compiler options (the optimised HLO's lines and the compile's CPU seconds,
less sensitive to a loaded machine than wall seconds). The equations are attributed to
the innermost linkopt function that emitted them; those made by differentiation carry
no source and count as ``(derivative)``. Printed, and written to
``benchmarks/results/program_size.json``.
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import tempfile
import time

import _results

os.environ["LINKOPT_CACHE_DIR"] = tempfile.mkdtemp(prefix="program_size_")

import jax  # noqa: E402
import jax.extend.core as jcore  # noqa: E402
from jax._src import source_info_util  # noqa: E402

from linkopt._config import COMPILER_OPTIONS  # noqa: E402
from linkopt._engine import programs  # noqa: E402
from linkopt._engine.lifting import padded  # noqa: E402
from linkopt._engine.structure import flatten, unflatten  # noqa: E402

PROGRAMS: dict[tuple, dict] = {}
ORIGINS: collections.Counter = collections.Counter()


def _origin(eqn) -> str:
    frame = source_info_util.user_frame(eqn.source_info.traceback)
    if frame is None:
        return "(derivative)"
    return f"{os.path.basename(frame.file_name)}:{frame.function_name}"


def _count(jaxpr, origins: collections.Counter) -> int:
    """Equations of ``jaxpr`` and of every jaxpr nested in its parameters."""
    total = 0
    for eqn in jaxpr.eqns:
        total += 1
        origins[_origin(eqn)] += 1
        for value in eqn.params.values():
            for sub in value if isinstance(value, (list, tuple)) else [value]:
                if isinstance(sub, jcore.ClosedJaxpr):
                    total += _count(sub.jaxpr, origins)
                elif isinstance(sub, jcore.Jaxpr):
                    total += _count(sub, origins)
    return total


def _measure(name, structure, fn, leaves, args, compile_it: bool) -> dict:
    def program(leaves, *args):
        return fn(unflatten(structure, leaves), *args)

    start = time.perf_counter()
    jaxpr = jax.make_jaxpr(program)(leaves, *args)
    row = {"program": name, "trace_s": time.perf_counter() - start}
    row["equations"] = _count(jaxpr.jaxpr, ORIGINS)
    if compile_it:
        lowered = jax.jit(program, compiler_options=COMPILER_OPTIONS).lower(
            leaves, *args
        )
        row["stablehlo_lines"] = lowered.as_text().count("\n")
        start = time.process_time()
        compiled = lowered.compile()
        row["compile_cpu_s"] = time.process_time() - start
        row["optimised_hlo_lines"] = (compiled.as_text() or "").count("\n")
    return row


def _hook(compile_it: bool):
    """Measure each program :func:`linkopt._engine.programs.call` is asked for, once
    per name, structure and argument shapes, before the call runs it."""
    original = programs.call

    def hooked(name, mech, fn, *args):
        leaves, structure = flatten(padded(mech))
        shapes = tuple(
            (jax.numpy.shape(x), str(jax.numpy.result_type(x)))
            for x in jax.tree_util.tree_leaves((leaves, args))
        )
        key = (name, structure, shapes)
        if key not in PROGRAMS:
            PROGRAMS[key] = _measure(name, structure, fn, leaves, args, compile_it)
        return original(name, mech, fn, *args)

    programs.call = hooked


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument("--no-compile", action="store_true")
    parser.add_argument("command", nargs="*")
    args = parser.parse_args()
    command = args.command or ["evaluate", "mechanisms/stewart.toml", "--json"]
    _hook(not args.no_compile)
    from linkopt._cli.main import main as cli

    stdout, sys.stdout = sys.stdout, open(os.devnull, "w")
    try:
        cli(command)
    finally:
        sys.stdout = stdout
    rows = sorted(PROGRAMS.values(), key=lambda r: -r["equations"])
    print(f"linkopt {' '.join(command)}: {sum(r['equations'] for r in rows)} equations")
    for r in rows:
        extra = (
            f"  StableHLO {r['stablehlo_lines']:6d} lines  optimised HLO "
            f"{r['optimised_hlo_lines']:6d} lines  compile "
            f"{r['compile_cpu_s']:5.1f} s CPU"
            if "compile_cpu_s" in r
            else ""
        )
        print(f"  {r['program']:<24} {r['equations']:7d} equations{extra}")
    print("equations by origin:")
    for origin, count in ORIGINS.most_common(args.top):
        print(f"  {count:7d}  {origin}")
    _results.write(
        __file__,
        {
            "command": command,
            "programs": rows,
            "origins": dict(ORIGINS.most_common(args.top)),
        },
    )


if __name__ == "__main__":
    main()
