"""Issue 41's breadth cases, synthesised and verified: the Jansen leg's foot path
from a leg perturbed by up to ±5 % per length, a spatial RSSR function generator
and a spherical four-bar's coupler path (the files and their closed forms:
``benchmarks/synthesis_spatial/generate.py``; the checks of the files:
``tests/test_synthesis_spatial.py``).

Run: ``nice -n 10 .venv/bin/python benchmarks/bench_synthesis_spatial.py
[--case NAME,...] [--particles N] [--iterations N]``

Each case runs ``linkopt.synthesis.synthesize`` on the shipped file (its design is
the start, its ``[synthesis]`` table the target) and sweeps the returned design
densely over its cycle (``linkopt.synthesis.verify``). Recorded per case: the
equivalent ``linkopt synthesize`` command, seconds (compilation included, from a
warm on-disk cache when run twice), RMS and largest distance at the targets (file
units; rad for the RSSR's output angle), the goal (a fraction of the stride, the
output's swing or the curve's extent), whether it is met, defect-free (the dense
sweep's verdict), the first defect if any, and the least forward σ_min over the
cycle. Results: ``benchmarks/results/bench_synthesis_spatial.json``.

A case whose goal the synthesis misses gets a ``polish`` record: a bounded
least-squares fit (``scipy.optimize.least_squares``, trust-region reflective) of the
distances at the targets from the synthesised design, its Jacobian by forward
differences on one batched score of the cycle (``linkopt._synth.objective.score``),
at most ``--polish`` evaluations, then the same dense sweep. It is a diagnosis, not
linkopt's method: it shows whether the miss is the first-order search's (a long
valley of the path error that capped gradient steps crawl along) or the problem's.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import _results
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
#: name: (file, goal fraction, what the fraction is of, particles, iterations)
CASES = {
    "jansen_foot": ("jansen_foot_path.toml", 0.005, "stride (x extent)", 32, 60),
    "rssr_function": ("rssr.toml", 0.01, "output swing", 16, 40),
    "spherical_path": ("spherical_four_bar.toml", 0.01, "largest extent", 16, 40),
}


def _range(targets, what: str) -> float:
    values = np.asarray(targets.values)
    if values.ndim == 1:
        return float(np.ptp(values))
    if what.startswith("stride"):
        return float(np.ptp(values[:, 0]))
    return float(np.ptp(values[:, :3], axis=0).max())


def run_case(
    name: str, particles: int | None, iterations: int | None, evaluations: int
) -> dict:
    import linkopt
    from linkopt import synthesis

    file, fraction, what, swarm, cap = CASES[name]
    particles, iterations = particles or swarm, iterations or cap
    path = ROOT / "mechanisms" / file
    mech = linkopt.load(path)
    targets = synthesis.load_targets(mech)
    settings = linkopt.OptimizerSettings(
        particles=particles, iterations=iterations, seed=0, spread=0.25, patience=5
    )
    began = time.perf_counter()
    initial = synthesis.score(mech, targets)
    result = synthesis.synthesize(mech, targets, settings, progress=_progress(name))
    report = synthesis.verify(mech, result)
    seconds = time.perf_counter() - began
    scale = _range(targets, what)
    row = {
        "case": name,
        "command": f"linkopt synthesize mechanisms/{file} --particles {particles} "
        f"--iterations {iterations} --seed 0 --out runs/{name}",
        "seconds": round(seconds, 2),
        "iterations": len(result.history),
        "initial_rms": initial.rms,
        "rms": result.rms,
        "max_distance": result.max_distance,
        "goal": f"RMS <= {fraction:g} x {what} ({fraction * scale:.4g})",
        "goal_met": bool(result.rms <= fraction * scale),
        "within_tolerance": bool(result.max_distance <= targets.tolerance),
        "defect_free": report.defect is None,
        "defect": report.defect,
        "least_sigma": float(report.least_sigma),
        "design": [float(v) for v in result.design],
    }
    if not row["goal_met"] and evaluations > 0:
        row["polish"] = polish(mech, targets, result.design, evaluations)
        row["polish"]["goal_met"] = bool(row["polish"]["rms"] <= fraction * scale)
    return row


def polish(mech, targets, design, evaluations: int, steps: int = 180) -> dict:
    """The ``polish`` record (module docstring)."""
    from scipy.optimize import least_squares

    from linkopt import synthesis
    from linkopt._design.evaluation import alpha_minus
    from linkopt._synth.objective import Problem, plan, score

    problem = Problem(targets, plan(mech, targets, steps, None))
    alpha = alpha_minus(mech)
    step = 1e-5 * np.maximum(mech.design.upper - mech.design.lower, 1.0)
    jacobian = {}

    def residuals(p: np.ndarray) -> np.ndarray:
        batch = np.vstack([p, p + np.diag(step)])
        d = np.asarray(score(mech, problem, batch, alpha).distances)
        jacobian["last"] = (d[1:] - d[0]).T / step
        return d[0]

    began = time.perf_counter()
    fit = least_squares(
        residuals, np.asarray(design, dtype=float), jac=lambda p: jacobian["last"],
        bounds=(mech.design.lower, mech.design.upper), max_nfev=evaluations,
    )  # fmt: skip
    result = synthesis.score(mech, targets, fit.x)
    report = synthesis.verify(mech, result)
    return {
        "evaluations": int(fit.nfev),
        "seconds": round(time.perf_counter() - began, 2),
        "rms": result.rms,
        "max_distance": result.max_distance,
        "within_tolerance": bool(result.max_distance <= targets.tolerance),
        "defect_free": report.defect is None,
        "defect": report.defect,
        "least_sigma": float(report.least_sigma),
        "design": [float(v) for v in fit.x],
    }


def _progress(name: str):
    def report(record: dict) -> None:
        print(
            f"{name}: iteration {record['iteration']:3d} RMS {record['rms']:.4g} "
            f"({'feasible' if record['feasible'] else 'not feasible'}) "
            f"{record['wall_time']:.1f} s",
            file=sys.stderr,
            flush=True,
        )

    return report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default=",".join(CASES))
    parser.add_argument("--particles", type=int)
    parser.add_argument("--iterations", type=int)
    parser.add_argument(
        "--polish", type=int, default=200, help="least-squares evaluations (0: none)"
    )
    args = parser.parse_args()
    rows = []
    for name in args.case.split(","):
        row = run_case(name, args.particles, args.iterations, args.polish)
        print({k: v for k, v in row.items() if k != "design"}, flush=True)
        rows.append(row)
    path = _results.write(__file__, {"cases": rows})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
