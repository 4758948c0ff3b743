"""Kinematics solve speed: linkopt's LM against scipy and optimistix on the same
residual.

Run: ``.venv/bin/python benchmarks/bench_kinematics.py [--quick]`` (the optimistix
comparison needs ``pip install -e '.[bench]'``)

Prints, for the five-bar and the Jansen leg: a single warm-started solve, solves per
second in batches of 1, 1 000 and 100 000 configurations, compile time with a cold and
a warm persistent cache (each in a fresh process), and the baselines as ratios.
Targets (five-bar, 2 cores): <= 200 µs a single solve, >= 30 000 solves/s batched
(issue 19: the Jansen leg >= 15 000). Last run (2026-12-03, idle machine, ``--quick``):
five-bar 16 845 solves/s in batches of 1000, a single warm-started solve 290 µs
pipelined (720 µs synchronised each call, a noisy figure: 410 µs earlier the same
day), a batch of one row 651/s (139/s when it ran as a padded block of 64); Jansen
6 947/s. Not met: a solve's time is its Cholesky factors and the normal equations
(:mod:`linkopt._engine.dense`; the README's "Architecture" says what would help).

Figures behind design choices in :mod:`linkopt._engine` (2 cores, measured when each
choice was made; rerun this script for today's):

* Plain-JAX linear algebra (:mod:`linkopt._engine.dense`) instead of jaxlib's LAPACK
  calls, so XLA keeps its default thread pool (``PJRT_NPROC`` is no longer set; the
  LAPACK kernels could deadlock it, :mod:`linkopt._config`). Measured on the shared
  2-core machine at load average ~12 (so only the ratios mean much), FK solves/s,
  before (LAPACK, ``PJRT_NPROC=1``) -> after (dense, default pool): five-bar batch 1
  4150 -> 2180, batch 1000 12 100 -> 12 500; Jansen batch 1 2750 -> 1050, batch 1000
  3760 -> 4820, batch 10 000 -> 4510. Single solves are slower (the factor and the
  solves are loops of 35-56 steps, each with XLA's per-iteration overhead); batches
  break even (five-bar) or gain (Jansen). Earlier, at load 3.7-8.5, the LAPACK code
  gave five-bar 2990 / 17 300 / 8970 and Jansen 3230 / 3970 / 2930 solves/s at
  batches 1 / 1000 / 100 000. ``PJRT_NPROC=1`` with LAPACK had been measured at
  19.4k solves/s against 10.8k with the default pool (five-bar, batches of 1e5).
* Batched solves in chunks of ``kinematics.CHUNK`` = 32 lanes (``lax.map``): one vmap
  over the whole batch made every step of the plain-JAX Cholesky stream all the
  batch's matrices through memory (1000 factors of 56 x 56: 200 ms in one vmap, 48 ms
  in chunks of 8, LAPACK 35 ms; 35 x 35: 27 ms, 21 ms in chunks of 32, LAPACK 16 ms).
  Panels of 8 columns per loop step were slower than one column (76 against 27 ms per
  1000 factors of 35 x 35), so only the triangular solves work by panels.
* Hand-written LM against ``optimistix.LevenbergMarquardt``: about 6x faster a solve.
* σ_min by block inverse iteration (:mod:`linkopt._engine.singularity`): the LAPACK SVD
  of a few dozen columns cost 0.2 ms per matrix and was 80 % of a design evaluation;
  for 180 five-bar states (two matrices each, one thread) the SVD took 64 ms and the
  iteration 26 ms, agreeing to 7e-5 relative with 4 sweeps. Forming ``A⁻¹`` once
  instead of two batched triangular solves per sweep (about 2.6 µs per 35 x 35 matrix
  and 6-column block): a 10-design five-bar evaluation 1.06 s -> 0.98 s.
* Jitting the residual and Jacobian entry points with the mechanism static: tracing a
  20-design evaluation 14.5 s -> 5 s.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MECHANISMS = {
    "five-bar": ROOT / "mechanisms/five_bar.toml",
    "jansen": ROOT / "mechanisms/jansen_1dof.toml",
}
TARGET_SINGLE_US = 200.0
TARGET_RATE = 30_000.0


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
    args = parser.parse_args()
    sizes = [1, 1000] if args.quick else [1, 1000, 100_000]
    import jax

    import linkopt

    print(f"jax {jax.__version__}, devices {jax.devices()}, {os.cpu_count()} CPU cores")
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
        _print_ours(ours, sizes, cold, warm)
        _print_baselines(mech, ours, scipy_)


def _print_ours(ours: dict, sizes: list[int], cold: float, warm: float) -> None:
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
    print(f"  target batched rate           {TARGET_RATE:10.0f} solves/s")
    print(f"  compile (load + 2 kernels)    cold {cold:.1f} s, warm cache {warm:.1f} s")


def _print_baselines(mech, ours: dict, scipy_: dict) -> None:
    try:
        optx = bench_optimistix(mech, 1000)
    except ImportError:
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


if __name__ == "__main__":
    main()
