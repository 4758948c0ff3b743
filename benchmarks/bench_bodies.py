"""Cost against the number of bodies: forward kinematics of generated chains and
ladders of closed loops (``tests/long_linkages.py``), dense factor against banded.

Run: ``.venv/bin/python benchmarks/bench_bodies.py [--sizes 10,30,100,300,1000]
[--dense-max 100] [--rows 16] [--repeats 3] [--keep]``

For each linkage and size: the time per solve of ``linkopt.solve_fk`` from the rest
pose (continuation, then Levenberg–Marquardt) for a batch of motor rows uniform
within ±``SPAN`` rad of rest, seed 0, with the dense factor of ``JᵀJ``
(``[solver] factor = "dense"``, the only one before issue 43) and the banded one
(:mod:`linkopt._engine.banded`), timed alternately (``--repeats`` times each, the
median kept) after one compiling call each, so a loaded machine slows both alike. The
dense factor runs up to ``--dense-max`` bodies (its assembly and factor grow with the
square and the cube of the bodies: at 300 bodies a solve takes minutes). The two
answers are compared where both run. Prints the log-log slope of time per solve, per
LM iteration and of the iterations per solve against bodies from 30 bodies on (issue
43's target: at most 1.2), and the extreme eigenvalues of ``JᵀJ`` at rest
(``--conditioning-sizes``: :func:`measure_conditioning`), which explain the LM
iterations a long soft linkage needs. Before that, the evaluation time per sample
(``--eval-sizes``: :func:`measure_evaluation`, dense and banded alike up to
``--eval-dense-max``), per sample step, and the fixed work of one step without its
solve (:func:`measure_point`: σ_min, its gradient and ``ds/da`` on the band), with
their slopes; ``--skip-fk`` times only the evaluation and keeps the FK figures of the
last results file; ``--keep`` keeps the last file's records of the linkages and sizes
not timed in this run (each with its own ``measured`` date), so the slow 1000-body
runs can be made alone. Beside each banded wall time, the process CPU time (all
threads) of the same runs, which a loaded machine's other work disturbs less (dotted
in the figure). Writes ``benchmarks/results/bench_bodies.json`` and draws
``figures/bench_bodies.png``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import time
from pathlib import Path

import _results
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

import long_linkages  # noqa: E402

#: Issue 43: fitted log-log slope of time per solve against bodies, from 30 bodies on.
TARGET_SLOPE = 1.2
#: Motor rows uniform within ±SPAN rad of rest. Both linkages magnify a motor's motion
#: with their length (the tongs' tip, the ladder's far end), and a first-order
#: prediction's error with it, so a wider span adds LM iterations as they grow; the
#: records keep the iterations per solve and the time per iteration beside it.
SPAN = 0.05
#: Lazy tongs of 500 scissors magnify a motor's turn so much that the continuation
#: needs hundreds of LM iterations per solve (measured: 564, 23.5 s per solve at 1000
#: bodies), which times the mechanism more than the factor: ``--rows-1000`` keeps that
#: run short (the records keep the iterations and the time per iteration).
CHAIN_MAX_NOTE = "lazy tongs of 1000 bodies need ~560 LM iterations per solve"


#: ``[evaluation] alpha_minus`` of the evaluated linkages: long lazy tongs stand near a
#: singularity at rest (σ_min 1e-4 at 100 bodies), where the default (twice ``f_sing``
#: at rest) is refused.
ALPHA_MINUS = 50.0


def _mechanism(kind: str, bodies: int, factor: str, evaluation: bool = False):
    from linkopt._files.fields import parse_toml
    from linkopt._files.loader import build

    if kind == "chain":
        text = long_linkages.chain(bodies)
    else:
        text = long_linkages.ladder(long_linkages.ladder_cells(bodies))
    if evaluation:
        text += f"\n[evaluation]\nalpha_minus = {ALPHA_MINUS}\n"
    # the load-time mobility check factors a dense Jacobian: not what is timed here
    mech = build(parse_toml(text, kind), kind, check=False)
    return dataclasses.replace(
        mech, solver=dataclasses.replace(mech.solver, factor=factor)
    )


def _solver(mech, motors):
    import jax

    from linkopt._engine.kinematics import solve_batch_from_rest

    def run():
        solution = solve_batch_from_rest(mech, "fk", motors, None)
        return jax.block_until_ready(solution)

    return run


def _timed(run) -> float:
    start = time.perf_counter()
    run()
    return time.perf_counter() - start


def measure(kind: str, bodies: int, rows: int, repeats: int, dense: bool) -> dict:
    factors = ("dense", "banded") if dense else ("banded",)
    mechs = {f: _mechanism(kind, bodies, f) for f in factors}
    mech = mechs["banded"]
    rng = np.random.default_rng(0)
    motors = rng.uniform(-SPAN, SPAN, size=(rows, mech.num_motors))
    runs = {f: _solver(m, motors) for f, m in mechs.items()}
    compile_s = {f: _timed(run) for f, run in runs.items()}
    times, cpu, answers = {f: [] for f in factors}, [], {}
    for _ in range(repeats):  # alternate, so load hits both alike
        for f in factors:
            start, start_cpu = time.perf_counter(), time.process_time()
            answers[f] = runs[f]()
            times[f].append((time.perf_counter() - start) / rows)
            if f == "banded":
                cpu.append((time.process_time() - start_cpu) / rows)
    record = {
        "linkage": kind,
        "bodies": mech.num_bodies,
        "rows": rows,
        "converged": float(np.mean(np.asarray(answers["banded"].converged))),
        "iterations": float(np.mean(np.asarray(answers["banded"].iterations))),
        "banded_s": statistics.median(times["banded"]),
        "banded_cpu_s": statistics.median(cpu),
        "banded_first_call_s": compile_s["banded"],
    }
    if record["iterations"]:  # none where the chord steps leave LM nothing to do
        record["banded_per_iteration_s"] = record["banded_s"] / record["iterations"]
    if dense:
        record["dense_s"] = statistics.median(times["dense"])
        record["dense_first_call_s"] = compile_s["dense"]
        record["ratio"] = record["dense_s"] / record["banded_s"]
        gap = np.asarray(answers["dense"].state) - np.asarray(answers["banded"].state)
        record["max_state_difference"] = float(np.max(np.abs(gap)))
    return record


def _evaluation(mech):
    import jax

    from linkopt._design.evaluation import evaluate

    def run():
        return jax.tree_util.tree_map(np.asarray, evaluate(mech))

    return run


def measure_evaluation(kind: str, bodies: int, repeats: int, dense: bool) -> dict:
    """``linkopt.evaluate`` of the file's design on the banded path (and the dense
    one where ``dense``): time per sample (the evaluation over its ``T`` targets, IK
    and adversarial minimisation each) and per sample step (over the steps its
    samples took), the first call (compiling) apart, the dense and banded answers
    compared."""
    factors = ("dense", "banded") if dense else ("banded",)
    mechs = {f: _mechanism(kind, bodies, f, True) for f in factors}
    runs = {f: _evaluation(m) for f, m in mechs.items()}
    compile_s = {f: _timed(run) for f, run in runs.items()}
    times, cpu, answers = {f: [] for f in factors}, [], {}
    for _ in range(repeats):  # alternate, so load hits both alike
        for f in factors:
            start, start_cpu = time.perf_counter(), time.process_time()
            answers[f] = runs[f]()
            times[f].append(time.perf_counter() - start)
            if f == "banded":
                cpu.append(time.process_time() - start_cpu)
    ev = answers["banded"]
    samples = int(ev.ik_iterations.size)
    steps = int(np.sum(ev.ik_iterations) + np.sum(ev.adv_iterations))
    record = {
        "linkage": kind,
        "bodies": mechs["banded"].num_bodies,
        "samples": samples,
        "sample_steps": steps,
        "f_design": float(ev.f_design),
        "banded_s": statistics.median(times["banded"]),
        "banded_first_call_s": compile_s["banded"],
    }
    record["banded_per_sample_s"] = record["banded_s"] / samples
    record["banded_cpu_per_sample_s"] = statistics.median(cpu) / samples
    record["banded_per_step_s"] = record["banded_s"] / steps
    if dense:
        other = answers["dense"]
        record["dense_s"] = statistics.median(times["dense"])
        record["dense_first_call_s"] = compile_s["dense"]
        record["dense_per_sample_s"] = record["dense_s"] / samples
        record["ratio"] = record["dense_s"] / record["banded_s"]
        record["same_steps"] = bool(
            np.array_equal(other.ik_iterations, ev.ik_iterations)
            and np.array_equal(other.adv_iterations, ev.adv_iterations)
        )
        record["f_design_dense"] = float(other.f_design)
        gap = np.abs(np.concatenate([other.adv_f_sing - ev.adv_f_sing]))
        record["max_f_sing_relative_difference"] = float(
            np.max(gap / np.abs(other.adv_f_sing))
        )
    return record


def measure_point(kind: str, bodies: int, repeats: int) -> dict:
    """The fixed work of one sample step on the band, its solve apart: σ_min of the
    FK and BK Jacobians with its gradient in the state, and ``ds/da``
    (:func:`linkopt._design.sampling.evaluate_point` with an objective that only
    returns them), at the rest pose; the median of ``repeats`` calls after the
    compiling one. What the per-step slope of the evaluation has beyond this is the
    solves' LM iterations."""
    import jax

    from linkopt._design.sampling import evaluate_point
    from linkopt._engine.geometry import geometry, rest_state

    mech = _mechanism(kind, bodies, "banded", True)
    geom, state = geometry(mech), rest_state(mech)
    motors = jax.numpy.zeros(mech.num_motors)

    def objective(motors, state, ds_da, f_sing, d_f_sing):
        return f_sing, d_f_sing @ ds_da, ds_da.T @ ds_da

    point = jax.jit(lambda s: evaluate_point(objective, mech, geom, motors, s))
    first = _timed(lambda: jax.block_until_ready(point(state)))
    times = [
        _timed(lambda: jax.block_until_ready(point(state))) for _ in range(repeats)
    ]
    return {
        "linkage": kind,
        "bodies": mech.num_bodies,
        "banded_point_s": statistics.median(times),
        "banded_point_first_call_s": first,
    }


def measure_conditioning(kind: str, bodies: int, sweeps: int = 40) -> dict:
    """The smallest and largest eigenvalues of the FK's ``JᵀJ`` at the rest pose, on
    the band: inverse iteration with its factor and power iteration with its
    product, ``sweeps`` each from a vector of ones. A long linkage soft across its
    length has a small smallest one, which slows the LM corrector's last digits
    (``linkopt._engine.banded.Banded``'s docstring)."""
    import jax.numpy as jnp

    from linkopt._engine import banded
    from linkopt._engine.geometry import geometry, rest_state

    mech = _mechanism(kind, bodies, "banded")
    geom, state = geometry(mech), rest_state(mech)
    _, band, _ = banded.normal_equations(
        mech, geom, "fk", jnp.zeros(mech.num_motors), state
    )
    lower = banded.factor(band, 0.0)
    low = high = jnp.ones((mech.num_bodies, 7)) / np.sqrt(7.0 * mech.num_bodies)
    for _ in range(sweeps):
        low = banded.cho_solve(lower, low)
        smallest = 1.0 / float(jnp.linalg.norm(low))
        low = low * smallest
        high = banded.matvec(band, high)
        largest = float(jnp.linalg.norm(high))
        high = high / largest
    return {
        "linkage": kind,
        "bodies": mech.num_bodies,
        "smallest_eigenvalue": smallest,
        "largest_eigenvalue": largest,
    }


def keep_last(records: list[dict], key: str) -> list[dict]:
    """``records`` and the last results file's ``key`` records of the linkages and
    sizes not in them (each with the ``measured`` date of that file, or its own)."""
    path = _results.RESULTS / "bench_bodies.json"
    if not path.exists():
        return records
    last = json.loads(path.read_text())
    done = {(r["linkage"], r["bodies"]) for r in records}
    kept = [
        {"measured": last["date"]} | r
        for r in last.get(key, [])
        if (r["linkage"], r["bodies"]) not in done
    ]
    order = lambda r: (r["linkage"], r["bodies"])  # noqa: E731
    return sorted(records + kept, key=order)


def slope(records: list[dict], key: str, smallest: int = 30) -> float | None:
    """Least-squares slope of ``log(time)`` against ``log(bodies)``, bodies >=
    ``smallest`` (records where ``key`` is missing or zero left out)."""
    pts = [
        (r["bodies"], r[key]) for r in records if r.get(key) and r["bodies"] >= smallest
    ]
    if len(pts) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def draw(records: list[dict], evaluations: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, right) = plt.subplots(1, 2, figsize=(11.0, 4.0))
    _panel(right, evaluations, "per_sample_s", "evaluation time per sample (s)")
    _panel(ax, records, "s", "time per FK solve from rest (s)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def _panel(ax, records: list[dict], suffix: str, ylabel: str) -> None:
    """Log-log time against bodies, dense dashed, banded solid and the banded runs'
    CPU time dotted, per linkage: the records' ``dense_<suffix>``,
    ``banded_<suffix>`` and ``banded_cpu_<suffix>`` where they have them."""
    for kind, marker in (("chain", "o"), ("ladder", "s")):
        rows = [r for r in records if r["linkage"] == kind]
        for name, style in (("dense", "--"), ("banded", "-"), ("banded_cpu", ":")):
            key = f"{name}_{suffix}"
            pts = [(r["bodies"], r[key]) for r in rows if key in r]
            if pts:
                x, y = zip(*pts, strict=True)
                ax.loglog(x, y, style, marker=marker, label=f"{kind}, {name}")
    ax.set_xlabel("bodies")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()


def _sizes(text: str) -> list[int]:
    return [int(v) for v in text.split(",") if v]


def _evaluations(args, kinds: list[str]) -> list[dict]:
    records = []
    for kind in kinds:
        for size in _sizes(args.eval_sizes):
            rec = measure_evaluation(
                kind, size, args.eval_repeats, size <= args.eval_dense_max
            )
            records.append(rec)
            line = f"{kind:6s} {rec['bodies']:5d} bodies: evaluate banded "
            line += f"{rec['banded_per_sample_s'] * 1e3:9.1f} ms/sample "
            line += f"({rec['sample_steps']} steps, first call "
            line += f"{rec['banded_first_call_s']:.0f} s)"
            if "dense_s" in rec:
                line += f", dense {rec['dense_per_sample_s'] * 1e3:9.1f} ms/sample "
                line += f"(x{rec['ratio']:.2f}, same steps {rec['same_steps']}, "
                line += f"f_sing rel. {rec['max_f_sing_relative_difference']:.1e})"
            print(line, flush=True)
    return records


def _points(args, kinds: list[str]) -> list[dict]:
    records = []
    for kind in kinds:
        for size in _sizes(args.point_sizes):
            rec = measure_point(kind, size, args.repeats)
            records.append(rec)
            print(
                f"{kind:6s} {rec['bodies']:5d} bodies: one step's σ_min, gradient "
                f"and ds/da {rec['banded_point_s'] * 1e3:8.2f} ms",
                flush=True,
            )
    return records


def _conditioning(args, kinds: list[str]) -> list[dict]:
    records = []
    for kind in kinds:
        for size in _sizes(args.conditioning_sizes):
            rec = measure_conditioning(kind, size)
            records.append(rec)
            print(
                f"{kind:6s} {rec['bodies']:5d} bodies: eigenvalues of JᵀJ at rest "
                f"{rec['smallest_eigenvalue']:.2e} to {rec['largest_eigenvalue']:.3g}",
                flush=True,
            )
    return records


def _fk(args, kinds: list[str]) -> list[dict]:
    records = []
    for kind in kinds:
        for size in _sizes(args.sizes):
            if kind == "chain" and size > args.chain_max:
                continue
            rows = args.rows if size < 1000 else args.rows_1000
            rec = measure(kind, size, rows, args.repeats, size <= args.dense_max)
            records.append(rec)
            line = f"{kind:6s} {rec['bodies']:5d} bodies: banded "
            line += (
                f"{rec['banded_s'] * 1e3:9.2f} ms/solve ({rec['iterations']:.1f} it)"
            )
            if "dense_s" in rec:
                line += f", dense {rec['dense_s'] * 1e3:9.2f} ms/solve "
                line += f"(x{rec['ratio']:.2f}, |Δs| {rec['max_state_difference']:.1e})"
            print(line, flush=True)
    return records


def _slopes(records: list[dict], keys: dict[str, str]) -> dict:
    """Per linkage, the slope from 30 bodies on of each record key in ``keys``."""
    return {
        kind: {
            name: slope([r for r in records if r["linkage"] == kind], key)
            for name, key in keys.items()
        }
        for kind in ("chain", "ladder")
    }


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10,30,100,300,1000")
    parser.add_argument("--kinds", default="chain,ladder")
    parser.add_argument("--dense-max", type=int, default=100)
    parser.add_argument(
        "--chain-max",
        type=int,
        default=1000,
        help=f"largest lazy tongs timed ({CHAIN_MAX_NOTE})",
    )
    parser.add_argument("--rows", type=int, default=16)
    parser.add_argument(
        "--rows-1000",
        type=int,
        default=16,
        help="motor rows at 1000 bodies and more (the tongs were timed with 2)",
    )
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--eval-sizes", default="10,30,100,300,1000")
    parser.add_argument("--point-sizes", default="30,100,300,1000")
    parser.add_argument("--eval-dense-max", type=int, default=30)
    parser.add_argument("--conditioning-sizes", default="30,100,300,1000")
    parser.add_argument("--eval-repeats", type=int, default=1)
    parser.add_argument("--skip-fk", action="store_true", help="time evaluation only")
    parser.add_argument(
        "--keep",
        action="store_true",
        help="keep the last results file's records of what this run does not time",
    )
    return parser


def main() -> None:
    args = _parser().parse_args()
    kinds = [k for k in args.kinds.split(",") if k]
    evaluations = _evaluations(args, kinds)
    points = _points(args, kinds)
    conditioning = _conditioning(args, kinds)
    records = [] if args.skip_fk else _fk(args, kinds)
    fk_from = None  # the FK figures are this run's
    if args.skip_fk:  # the FK figures of the last full run stay
        kept = json.loads((_results.RESULTS / "bench_bodies.json").read_text())
        records = kept["fk_per_solve"]
        fk_from = kept.get("fk_measured") or {k: kept[k] for k in ("date", "commit")}
    if args.keep:
        evaluations = keep_last(evaluations, "evaluation_per_sample")
        points = keep_last(points, "evaluation_step_without_solve")
        conditioning = keep_last(conditioning, "conditioning_at_rest")
        records = records if args.skip_fk else keep_last(records, "fk_per_solve")
    eval_slopes = _slopes(
        evaluations,
        {
            "per_sample": "banded_per_sample_s",
            "cpu_per_sample": "banded_cpu_per_sample_s",
            "per_step": "banded_per_step_s",
        },
    )
    eval_slopes = {
        kind: v | _slopes(points, {"step_without_solve": "banded_point_s"})[kind]
        for kind, v in eval_slopes.items()
    }
    slopes = _slopes(
        records,
        {
            "banded": "banded_s",
            "banded_cpu": "banded_cpu_s",
            "banded_per_iteration": "banded_per_iteration_s",
            "iterations": "iterations",
            "dense": "dense_s",
        },
    )
    for kind in kinds:
        print(f"{kind}: evaluation log-log slope from 30 bodies: {eval_slopes[kind]}")
        print(
            f"{kind}: FK log-log slope from 30 bodies: {slopes[kind]} (target <= 1.2)"
        )
    draw(records, evaluations, ROOT / "figures" / "bench_bodies.png")
    _results.write(
        "bench_bodies",
        {
            "fk_per_solve": records,
            "fk_measured": fk_from,
            "slope_from_30_bodies": slopes,
            "target_slope": TARGET_SLOPE,
            "evaluation_per_sample": evaluations,
            "evaluation_step_without_solve": points,
            "evaluation_slope_from_30_bodies": eval_slopes,
            "conditioning_at_rest": conditioning,
        },
    )


if __name__ == "__main__":
    main()
