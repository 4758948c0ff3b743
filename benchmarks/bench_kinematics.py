"""Kinematics solve speed: linkopt's LM against scipy and optimistix on the same
residual.

Run: ``.venv/bin/python benchmarks/bench_kinematics.py [--quick] [--wide-only]
[--beyond-only] [--before TREE]`` (the optimistix comparison needs
``pip install -e '.[bench]'``; ``--before`` runs the sweeps from rest, :data:`WIDE` and
:data:`BEYOND`, on another checkout's code too, alternating with this one's, and
prints the ratios)

:data:`BEYOND` is a sweep that reaches past the linkages' reach: rows within
±``BEYOND_SPAN`` of rest, of which some have no assembly on the rest branch. Such a row
fails only once its continuation has halved its step down to ``continuation.MIN_STEP``
at the edge of the reach, so its cost is the LM iterations of the steps it rejects
(``continuation.STEP_ITERATIONS`` caps each); it is printed as solves per second and
the mean LM iterations of a failing row; ``--beyond-only`` keeps it in
``benchmarks/results/bench_kinematics_beyond.json``.

Prints, for the five-bar and the Jansen leg: a single warm-started solve, solves per
second in batches of 1, 1 000 and 100 000 configurations, compile time with a cold and
a warm persistent cache (each in a fresh process), and the baselines as ratios, against
the targets ``TARGET_SINGLE_US`` and ``TARGET_RATE`` (issue 19, 2 cores); writes them to
``benchmarks/results/bench_kinematics.json``.

The choices behind these figures are documented where they are made: the hand-written
Levenberg–Marquardt (:mod:`linkopt._engine.solvers.lm`), plain-JAX linear algebra and
its one-column Cholesky (:mod:`linkopt._engine.dense`), batches in chunks of
``kinematics.CHUNK`` lanes (:mod:`linkopt._engine.kinematics`), σ_min by block inverse
iteration (:mod:`linkopt._engine.singularity`), the Jacobian entry points jitted with
the mechanism static (:mod:`linkopt._engine.jacobian`). Where a solve's time goes, and
what would make it faster: the documentation's Architecture page.
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
MECHANISMS = {
    "five-bar": ROOT / "mechanisms/five_bar.toml",
    "jansen": ROOT / "mechanisms/jansen_1dof.toml",
}
#: Microseconds of a single warm-started solve (five-bar).
TARGET_SINGLE_US = 200.0
#: Batched solves per second.
TARGET_RATE = {"five-bar": 30_000.0, "jansen": 15_000.0}
#: A user's sweep (issue 28): ``linkopt.solve_fk`` from the rest pose of 1000 motor
#: rows uniform within ±``WIDE_SPAN`` rad of rest, and its target in solves per second
#: (issue 43's; issue 28's were 30 000 and 15 000).
WIDE = {
    "five-bar": (ROOT / "mechanisms/five_bar.toml", 100_000.0),
    "jansen_2dof": (ROOT / "mechanisms/jansen_2dof.toml", 50_000.0),
}
WIDE_SPAN = 0.3
#: A sweep past the reach (module docstring): 256 rows uniform within ±``BEYOND_SPAN``
#: rad (or reference lengths) of rest. Before ``continuation.STEP_ITERATIONS``
#: (2026-12-07, 2 cores, one run): five-bar 197-224 solves/s with 11 % of the rows
#: failing after about 760 LM iterations each; Stewart platform 98 % failing after 876.
BEYOND = {
    "five-bar": ROOT / "mechanisms/five_bar.toml",
    "neck_2dof": ROOT / "mechanisms/neck_2dof.toml",
    "stewart": ROOT / "mechanisms/stewart.toml",
}
BEYOND_SPAN = 1.0


def _timed(fn, repeats: int) -> float:
    import jax

    jax.block_until_ready(fn())
    start = time.perf_counter()
    for _ in range(repeats):
        jax.block_until_ready(fn())
    return (time.perf_counter() - start) / repeats


def _pipelined(fn, repeats: int) -> float:
    """Time per call when calls are issued back to back and synchronised once at the
    end."""
    import jax

    jax.block_until_ready(fn())
    start = time.perf_counter()
    for _ in range(repeats):
        out = fn()
    jax.block_until_ready(out)
    return (time.perf_counter() - start) / repeats


def _motor_batch(mech, n: int, seed: int = 0):
    import numpy as np

    return (
        np.random.default_rng(seed).uniform(-0.05, 0.05, size=(n, mech.num_motors))
        * mech.motor_scale
    )


def bench_linkopt(mech, sizes) -> dict:
    import numpy as np

    import linkopt

    single = _motor_batch(mech, 1)[0]
    call = lambda: linkopt.solve_fk(mech, single).state  # noqa: E731
    result = {
        "single_us": 1e6 * _timed(call, 300),
        "single_pipelined_us": 1e6 * _pipelined(call, 2000),
    }
    for n in sizes:
        batch = _motor_batch(mech, n)
        seconds = _timed(
            lambda batch=batch: linkopt.solve_fk(mech, batch).state,
            3 if n >= 100_000 else 20,
        )
        converged = float(np.mean(np.asarray(linkopt.solve_fk(mech, batch).converged)))
        result[f"rate_{n}"] = n / seconds
        result[f"converged_{n}"] = converged
    return result


def bench_wide(mech, repeats: int = 7) -> tuple[float, float]:
    """Median solves per second of :data:`WIDE`'s batch, and the fraction converged."""
    import numpy as np

    import linkopt

    rest = np.asarray(linkopt.motor_values(mech, linkopt.rest_state(mech)))
    span = WIDE_SPAN * mech.motor_scale
    rows = rest + np.random.default_rng(0).uniform(-span, span, (1000, rest.size))
    solve = lambda: linkopt.solve_fk(mech, rows).state  # noqa: E731
    times = [_timed(solve, 3) for _ in range(repeats)]
    converged = float(np.mean(np.asarray(linkopt.solve_fk(mech, rows).converged)))
    return 1000 / float(np.median(times)), converged


def bench_beyond(mech, repeats: int = 3) -> tuple[float, float, float]:
    """:data:`BEYOND`'s sweep: best solves per second, the fraction converged, and the
    mean LM iterations of the rows that failed (0 where none did)."""
    import numpy as np

    import linkopt

    rest = np.asarray(linkopt.motor_values(mech, linkopt.rest_state(mech)))
    span = BEYOND_SPAN * mech.motor_scale
    rows = rest + np.random.default_rng(0).uniform(-span, span, (256, rest.size))
    solve = lambda: linkopt.solve_fk(mech, rows).state  # noqa: E731
    best = min(_timed(solve, 1) for _ in range(repeats))
    solution = linkopt.solve_fk(mech, rows)
    converged = np.asarray(solution.converged)
    failed = np.asarray(solution.iterations)[~converged]
    mean = float(failed.mean()) if failed.size else 0.0
    return 256 / best, float(converged.mean()), mean


def bench_optimistix(mech, n: int) -> dict:
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    import linkopt
    from linkopt._engine.constraints import fk_residual

    geom = linkopt.geometry(mech)
    start = linkopt.rest_state(mech)
    solver = optx.LevenbergMarquardt(rtol=1e-12, atol=1e-12)

    def solve(a):
        fn = lambda s, args: fk_residual(mech, geom, args / mech.motor_scale, s)  # noqa: E731
        return optx.least_squares(
            fn, solver, start, args=a, max_steps=100, throw=False
        ).value

    single = jax.jit(solve)
    batched = jax.jit(jax.vmap(solve))
    a1 = jnp.asarray(_motor_batch(mech, 1)[0])
    batch = jnp.asarray(_motor_batch(mech, n))
    return {
        "single_us": 1e6 * _timed(lambda: single(a1), 100),
        f"rate_{n}": n / _timed(lambda: batched(batch), 5),
    }


def bench_scipy(mech) -> dict:
    import jax
    import numpy as np
    from scipy.optimize import least_squares

    import linkopt
    from linkopt._engine.constraints import fk_residual

    geom = linkopt.geometry(mech)
    a = _motor_batch(mech, 1)[0] / mech.motor_scale
    residual = jax.jit(lambda s: fk_residual(mech, geom, a, s))
    start = np.asarray(linkopt.rest_state(mech))
    fn = lambda s: np.asarray(residual(s))  # noqa: E731
    fn(start)
    t0 = time.perf_counter()
    for _ in range(5):
        least_squares(fn, start, method="lm", xtol=1e-14, ftol=1e-14)
    return {"single_us": 1e6 * (time.perf_counter() - t0) / 5}


def compile_seconds(path: Path, cache: str) -> float:
    """Wall time of load + first FK solve + first batched solve in a fresh process."""
    code = (
        "import time; t=time.perf_counter(); import numpy as np, linkopt;"
        "linkopt.use_cache();"
        f"m=linkopt.load({str(path)!r});"
        "linkopt.solve_fk(m, np.zeros(m.num_motors)).state.block_until_ready();"
        "linkopt.solve_fk(m, np.zeros((1000, m.num_motors))).state.block_until_ready();"
        "print(time.perf_counter()-t)"
    )
    env = dict(os.environ, LINKOPT_CACHE_DIR=cache)
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="skip the 100 000 batch")
    parser.add_argument(
        "--wide-only", action="store_true", help="only the sweep from rest (WIDE)"
    )
    parser.add_argument(
        "--beyond-only", action="store_true", help="only the sweep past the reach"
    )
    parser.add_argument(
        "--before",
        type=Path,
        help="another checkout: the sweep from rest with its code too, alternating",
    )
    parser.add_argument("--out", default=str(_results.RESULTS))
    args = parser.parse_args()
    sizes = [1, 1000] if args.quick else [1, 1000, 100_000]
    import jax

    import linkopt

    print(f"jax {jax.__version__}, devices {jax.devices()}, {os.cpu_count()} CPU cores")
    figures = {"jax": jax.__version__, "solves": [], "batches": [], "baselines": []}
    if not args.beyond_only:
        wide = _wide() if args.before is None else _wide_against(args.before)
        figures["wide"] = wide
    if not args.wide_only:
        figures["beyond"] = _beyond(args.before)
    if args.beyond_only:  # its own record, beside the whole run's
        beyond = {"jax": jax.__version__, "beyond": figures["beyond"]}
        _results.write(__file__.replace(".py", "_beyond.py"), beyond, args.out)
        return
    if args.wide_only:
        _results.write(__file__, figures, args.out)
        return
    for name, path in MECHANISMS.items():
        if not path.exists():
            print(f"\n{name}: {path} missing, skipped")
            continue
        mech = linkopt.load(path)
        with tempfile.TemporaryDirectory() as cache:
            cold = compile_seconds(path, cache)
            warm = compile_seconds(path, cache)
        ours = bench_linkopt(mech, sizes)
        scipy_ = bench_scipy(mech)
        print(f"\n{name}: |s| = {mech.state_size}")
        _print_ours(ours, sizes, cold, warm, TARGET_RATE[name])
        optx = _print_baselines(mech, ours, scipy_)
        compiled = {"compile_cold_s": cold, "compile_warm_s": warm}
        _record(figures, name, mech, sizes, compiled, ours, optx, scipy_)
    _results.write(__file__, figures, args.out)


def _wide() -> list[dict]:
    """:func:`bench_wide` of every :data:`WIDE` mechanism, printed and as rows."""
    import linkopt

    rows = []
    print(f"\nsolve_fk from rest, 1000 rows within ±{WIDE_SPAN} rad:")
    for name, (path, target) in WIDE.items():
        rate, converged = bench_wide(linkopt.load(path))
        verdict = "met" if rate >= target else "not met"
        print(
            f"  {name:<12} {rate:10.0f} solves/s (target {target:,.0f}, {verdict}),"
            f" {100 * converged:.1f} % converged"
        )
        rows.append(
            {"mechanism": name, "solves_per_s": rate, "target": target,
             "converged": converged}
        )  # fmt: skip
    return rows


def _beyond(before: Path | None, rounds: int = 2) -> list[dict]:
    """:func:`bench_beyond` of every :data:`BEYOND` mechanism in fresh processes,
    alternating with ``before``'s code where given, printed and as rows."""
    rows = []
    print(f"\nsolve_fk from rest, 256 rows within ±{BEYOND_SPAN} (past the reach):")
    trees = {"after": ROOT} if before is None else {"before": before, "after": ROOT}
    with tempfile.TemporaryDirectory() as scratch:
        for name, path in BEYOND.items():
            runs = {side: [] for side in trees}
            for _ in range(rounds):
                for side, tree in trees.items():
                    cache = str(Path(scratch) / side)
                    runs[side].append(_wide_run(tree.resolve(), path, cache, "beyond"))
            best = {k: max(v, key=lambda r: r["solves_per_s"]) for k, v in runs.items()}
            line = (
                f"  {name:<12} {best['after']['solves_per_s']:8.0f} solves/s,"
                f" {100 * best['after']['converged']:.0f} % converged, failing rows"
                f" {best['after']['failed_iterations']:.0f} LM iterations"
            )
            if before is not None:
                ratio = best["after"]["solves_per_s"] / best["before"]["solves_per_s"]
                line += (
                    f"; before {best['before']['solves_per_s']:.0f} solves/s,"
                    f" {best['before']['failed_iterations']:.0f} iterations,"
                    f" ratio {ratio:.2f}"
                )
            print(line)
            rows.append({"mechanism": name, **best["after"], "runs": runs})
    return rows


def _wide_run(tree: Path, path: Path, cache: str, which: str = "wide") -> dict:
    """:func:`bench_wide` (``which`` "beyond": :func:`bench_beyond`) of ``path`` in a
    fresh process on ``tree``'s code (this file's functions, ``tree``'s package), with
    the load average before it."""
    code = (
        f"import sys, json; sys.path.insert(0, {str(Path(__file__).parent)!r});"
        "import linkopt, bench_kinematics as b; linkopt.use_cache();"
        f"print(json.dumps(b.bench_{which}(linkopt.load({str(path)!r}))))"
    )
    env = dict(os.environ, PYTHONPATH=str(tree), LINKOPT_CACHE_DIR=cache)
    load = os.getloadavg()[0]
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=tree, capture_output=True,
        text=True, check=True,
    )  # fmt: skip
    figures = json.loads(out.stdout.strip().splitlines()[-1])
    names = ["solves_per_s", "converged", "failed_iterations"]
    return {**dict(zip(names, figures)), "load": load}


def _wide_against(before: Path, rounds: int = 3) -> list[dict]:
    """:data:`WIDE` on ``before``'s code and this checkout's, alternating in each of
    ``rounds`` (each tree keeps its own cache folder, so only the first round
    compiles), printed with the after/before ratio of the best rates."""
    rows = []
    print(f"\nsolve_fk from rest, 1000 rows within ±{WIDE_SPAN} rad, against {before}:")
    with tempfile.TemporaryDirectory() as old, tempfile.TemporaryDirectory() as new:
        for name, (path, target) in WIDE.items():
            runs = {"before": [], "after": []}
            for _ in range(rounds):
                runs["before"].append(_wide_run(before.resolve(), path, old))
                runs["after"].append(_wide_run(ROOT, path, new))
            best = {k: max(r["solves_per_s"] for r in v) for k, v in runs.items()}
            loads = [r["load"] for v in runs.values() for r in v]
            ratio = best["after"] / best["before"]
            print(
                f"  {name:<12} {best['after']:10.0f} solves/s (target {target:,.0f}),"
                f" before {best['before']:.0f}, ratio {ratio:.2f}"
                f" (load {min(loads):.1f}-{max(loads):.1f})"
            )
            rows.append(
                {"mechanism": name, "solves_per_s": best["after"], "target": target,
                 "converged": runs["after"][-1]["converged"],
                 "before": best["before"], "before_tree": str(before.resolve()),
                 "runs": runs}
            )  # fmt: skip
    return rows


def _record(figures: dict, name: str, mech, sizes, compiled, ours, optx, scipy_):
    """One mechanism's figures as rows of the results file's three tables."""
    figures["solves"].append(
        {
            "mechanism": name,
            "state_size": mech.state_size,
            "single_us": ours["single_us"],
            "single_pipelined_us": ours["single_pipelined_us"],
            "target_single_us": TARGET_SINGLE_US,
            **compiled,
        }
    )
    figures["batches"] += [
        {
            "mechanism": name,
            "batch": n,
            "solves_per_s": ours[f"rate_{n}"],
            "target": TARGET_RATE[name],
            "converged": ours[f"converged_{n}"],
        }
        for n in sizes
    ]
    for solver, result in (("linkopt", ours), ("optimistix", optx), ("scipy", scipy_)):
        if result is not None:
            figures["baselines"].append(
                {
                    "mechanism": name,
                    "solver": solver,
                    "single_us": result["single_us"],
                    "rate_1000": result.get("rate_1000"),
                }
            )


def _print_ours(
    ours: dict, sizes: list[int], cold: float, warm: float, target_rate: float
) -> None:
    print(
        f"  single warm-started solve     {ours['single_us']:10.1f} µs   "
        f"synchronised each call (target <= {TARGET_SINGLE_US:.0f} µs)"
    )
    print(
        f"  single, calls pipelined       {ours['single_pipelined_us']:10.1f} µs   "
        "per call, synchronised once"
    )
    for n in sizes:
        print(
            f"  batch {n:>7}                 {ours[f'rate_{n}']:10.0f} solves/s "
            f"(converged {ours[f'converged_{n}']:.3f})"
        )
    print(f"  target batched rate           {target_rate:10.0f} solves/s")
    print(f"  compile (load + 2 kernels)    cold {cold:.1f} s, warm cache {warm:.1f} s")


def _print_baselines(mech, ours: dict, scipy_: dict) -> dict | None:
    """Print the baselines beside ours; optimistix's figures, None without it."""
    try:
        optx = bench_optimistix(mech, 1000)
    except ImportError:
        optx = None
        print("  optimistix LM                 skipped (pip install -e '.[bench]')")
    else:
        print(
            f"  optimistix LM single          {optx['single_us']:10.1f} µs   "
            f"ratio {optx['single_us'] / ours['single_us']:.1f}x slower"
        )
        print(
            f"  optimistix LM batch 1000      {optx['rate_1000']:10.0f} solves/s "
            f"ratio {ours['rate_1000'] / optx['rate_1000']:.1f}x slower"
        )
    print(
        f"  scipy least_squares(lm) FD    {scipy_['single_us']:10.1f} µs   "
        f"ratio {scipy_['single_us'] / ours['single_us']:.0f}x slower"
    )
    return optx


if __name__ == "__main__":
    main()
