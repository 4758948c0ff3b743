"""Command line: ``linkopt check | fk | bk | evaluate | plot | verify | optimize``; a
thin layer over the public API.

Bad input exits with status 2 and one line on stderr; a failed solve exits with 1.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
from pathlib import Path

import numpy as np

from .._design.evaluation import alpha_minus, evaluate
from .._engine.kinematics import solve_bk, solve_bk_path, solve_fk, solve_fk_path
from .._engine.loader import load
from .._engine.readout import output_values
from .._errors import InputError, LinkoptError
from . import arm as arm_commands
from . import manipulability as manipulability_commands
from . import payloads
from . import trace as trace_commands


def _parse_row(text: str, names: tuple[str, ...], where: str) -> list[float]:
    expected, what = len(names), ", ".join(names)
    cells = [c.strip() for c in text.split(",") if c.strip() != ""]
    try:
        values = [float(c) for c in cells]
    except ValueError:
        raise InputError(
            f"{where}: expected {expected} comma-separated numbers ({what}), got {text!r}"
        ) from None
    if len(values) != expected or not np.all(np.isfinite(values)):
        raise InputError(
            f"{where}: expected {expected} finite numbers ({what}), got {len(values)}: {text!r}"
        )
    return values


def _read_values(
    arg: str, names: tuple[str, ...], what: str
) -> tuple[np.ndarray, bool]:
    """Values from ``v1,v2,...`` or a CSV file of rows (optional header); returns
    (values, is_path)."""
    path = Path(arg)
    if not (arg.lower().endswith(".csv") or path.is_file()):
        return np.array(_parse_row(arg, names, f"--{what}")), False
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as err:
        raise InputError(f"{arg}: cannot read CSV file ({err.strerror})") from None
    rows = [r for r in csv.reader(lines) if any(c.strip() for c in r)]
    if rows and rows[0] and not _is_number(rows[0][0]):
        header = [c.strip() for c in rows[0]]
        if header != list(names):
            raise InputError(
                f"{arg}: line 1: header {header} does not match the {what} {list(names)}"
            )
        rows = rows[1:]
    if not rows:
        raise InputError(f"{arg}: no data rows")
    values = [
        _parse_row(",".join(r), names, f"{arg}: row {k + 1}")
        for k, r in enumerate(rows)
    ]
    return np.array(values), True


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _print_table(title: str, items: dict) -> None:
    print(title)
    for key, value in items.items():
        print(f"  {key:<18} {value}")


def _cmd_check(args) -> int:
    mech = load(args.file)
    info = payloads.summary(mech)
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"{info['name']} ({info['file']}): OK")
    sizes = {
        k: info[k]
        for k in ("state_size", "mobility", "design_parameters", "reference_length")
    }
    sizes["constraint_rows"] = (
        f"FK {info['constraint_rows']['fk']}, BK {info['constraint_rows']['bk']}"
    )
    sizes["bodies"] = ", ".join(info["bodies"])
    _print_table("sizes", sizes)
    _print_table(
        "motors", {k: f"{v['kind']} at {v['joint']}" for k, v in info["motors"].items()}
    )
    _print_table(
        "outputs",
        {
            k: f"{v['kind']} in [{v['min']:g}, {v['max']:g}]"
            for k, v in info["outputs"].items()
        },
    )
    _print_table(
        "parameters",
        {
            k: f"{v['initial']:g} in [{v['min']:g}, {v['max']:g}]"
            for k, v in info["parameters"].items()
        },
    )
    _print_table(
        "joints (rest anchor)",
        {k: f"{v['type']:<11} {v['anchor']}" for k, v in info["joints"].items()},
    )
    return 0


def _solve_command(args, kind: str) -> int:
    mech = load(args.file)
    names = mech.motor_names if kind == "fk" else mech.output_names
    what = "motors" if kind == "fk" else "outputs"
    values, is_path = _read_values(getattr(args, what), names, what)
    if is_path:
        solver = solve_fk_path if kind == "fk" else solve_bk_path
    else:
        solver = solve_fk if kind == "fk" else solve_bk
    solution = solver(mech, values)
    states = np.atleast_2d(np.asarray(solution.state))
    converged = np.atleast_1d(np.asarray(solution.converged))
    residual = np.atleast_1d(np.asarray(solution.residual))
    records = [
        payloads.configuration(mech, s, c, r)
        for s, c, r in zip(states, converged, residual)
    ]
    payload = (
        {"converged": bool(converged.all()), "path": records} if is_path else records[0]
    )
    if args.json:
        print(json.dumps(payload, indent=2))
    else:
        for k, rec in enumerate(records):
            label = f"row {k + 1}" if is_path else kind.upper()
            print(
                f"{label}: converged={rec['converged']} residual={rec['residual']:.2e} f_sing={rec['f_sing']:.4g} (σ_min FK {rec['sigma_min_fk']:.4g}, BK {rec['sigma_min_bk']:.4g})"
            )
            print(
                "  motors  "
                + ", ".join(f"{n}={v:.6g}" for n, v in rec["motors"].items())
            )
            print(
                "  outputs "
                + ", ".join(f"{n}={v:.6g}" for n, v in rec["outputs"].items())
            )
            if not is_path:
                for n, p in {**rec["joints"], **rec["points"]}.items():
                    print(f"  {n:<16} ({p[0]:.6g}, {p[1]:.6g}, {p[2]:.6g})")
    if not converged.all():
        first = int(np.argmin(converged))
        where = f" at row {first + 1}" if is_path else ""
        print(
            f"linkopt: error: {kind.upper()} solve failed{where}: residual {residual[first]:.2e} (no assembly reached from the start state)",
            file=sys.stderr,
        )
        return 1
    return 0


def _design_arg(mech, text: str | None) -> np.ndarray | None:
    """``--design``: comma-separated values in parameter order, or a mechanism file
    whose parameters (same names) hold the design."""
    if text is None:
        return None
    names = mech.design.names
    if text.lower().endswith(".toml"):
        other = load(text)
        if other.design.names != names:
            raise InputError(
                f"{text}: parameters {list(other.design.names)} do not match those of {mech.source}: {list(names)}"
            )
        return other.design.p0
    values = np.array(_parse_row(text, names, "--design"))
    outside = (values < mech.design.lower) | (values > mech.design.upper)
    if np.any(outside):
        k = int(np.argmax(outside))
        raise InputError(
            f"--design: {names[k]} = {values[k]:g} is outside its bounds [{mech.design.lower[k]:g}, {mech.design.upper[k]:g}]"
        )
    return values


def _evaluation_payload(mech, ev) -> dict:
    from .._design.evaluation import targets

    ik_out = np.asarray(output_values(mech, ev.ik_states))
    adv_out = np.asarray(output_values(mech, ev.adv_states))
    samples = []
    for t, goal in enumerate(targets(mech)):
        samples.append(
            {
                "target": dict(zip(mech.output_names, map(float, goal))),
                "ik": {
                    "motors": dict(
                        zip(
                            mech.motor_names,
                            map(float, np.asarray(ev.ik_motors[t]) * mech.motor_scale),
                        )
                    ),
                    "reached": dict(zip(mech.output_names, map(float, ik_out[t]))),
                    "f_bk": float(ev.ik_reach[t]),
                    "f_sing": float(ev.ik_f_sing[t]),
                },
                "adversarial": {
                    "motors": dict(
                        zip(
                            mech.motor_names,
                            map(float, np.asarray(ev.adv_motors[t]) * mech.motor_scale),
                        )
                    ),
                    "outputs": dict(zip(mech.output_names, map(float, adv_out[t]))),
                    "f_sing": float(ev.adv_f_sing[t]),
                    "culled": float(ev.adv_culled[t]),
                },
            }
        )
    return {
        "f_design": float(ev.f_design),
        "reach": float(ev.reach),
        "singularity": float(ev.singularity),
        "regularizer": float(ev.regularizer),
        "alpha_minus": alpha_minus(mech),
        "samples": samples,
    }


def _cmd_evaluate(args) -> int:
    mech = load(args.file)
    design = _design_arg(mech, args.design)
    payload = _evaluation_payload(mech, evaluate(mech, design))
    if args.json:
        print(json.dumps(payload, indent=2))
        return 0
    print(
        f"{mech.name}: f_design = {payload['f_design']:.4g} (reach {payload['reach']:.4g}, singularity {payload['singularity']:.4g}); regulariser {payload['regularizer']:.4g}; α₋ = {payload['alpha_minus']:.4g}"
    )
    print(
        f"  {'target':<22} {'IK reached':<22} {'f_BK':>9} {'f_sing IK':>10} {'f_sing adv':>10} {'culled':>9}"
    )
    for sample in payload["samples"]:
        target = ", ".join(f"{v:.4g}" for v in sample["target"].values())
        reached = ", ".join(f"{v:.4g}" for v in sample["ik"]["reached"].values())
        print(
            f"  {target:<22} {reached:<22} {sample['ik']['f_bk']:9.2e} {sample['ik']['f_sing']:10.4g} {sample['adversarial']['f_sing']:10.4g} {sample['adversarial']['culled']:9.3g}"
        )
    return 0


def _cmd_plot(args) -> int:
    from .._design.plots import plot_mechanism, plot_spaces

    mech = load(args.file)
    design = _design_arg(mech, args.design)
    if args.resolution < 8:
        raise InputError(
            f"--resolution: expected at least 8 cells per axis, got {args.resolution}"
        )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    label = args.label or ("initial" if design is None else "design")
    stem = Path(args.file).stem
    if mech.num_motors == mech.num_outputs and mech.num_motors in (2, 3):
        print(f"evaluating {mech.name} ...", file=sys.stderr)
        ev = evaluate(mech, design)
        grids = "grids" if mech.num_motors == 2 else "grids (three 2-D sections each)"
        print(
            f"solving the {args.resolution}x{args.resolution} motor and end-effector {grids} ...",
            file=sys.stderr,
        )
        print(
            plot_spaces(
                mech,
                ev,
                out / f"{stem}_{label}.png",
                resolution=args.resolution,
                design=design,
            )
        )
    else:
        print(
            f"{args.file}: space plots need 2 or 3 motors and outputs, the file has {mech.num_motors}; drawing the mechanism only",
            file=sys.stderr,
        )
    print(
        plot_mechanism(
            mech, out / f"{stem}_{label}_mechanism.png", designs={label: design}
        )
    )
    return 0


def _verification_payload(mech, result) -> dict:
    return {
        "passed": result.passed,
        "coverage": result.coverage,
        "cells": result.cells,
        "grid": list(result.grid_shape),
        "threshold_alpha_minus": result.threshold,
        "max_f_sing": result.max_f_sing,
        "min_sigma_fk": result.min_sigma_fk,
        "min_sigma_bk": result.min_sigma_bk,
        "worst_cell": dict(zip(mech.output_names, map(float, result.worst_outputs))),
        "unreached_example": None
        if result.unreached_example is None
        else dict(zip(mech.output_names, map(float, result.unreached_example))),
    }


def _cmd_verify(args) -> int:
    from .._design.verify import verify

    mech = load(args.file)
    design = _design_arg(mech, args.design)
    if args.resolution is not None and args.resolution < 2:
        raise InputError(
            f"--resolution: expected at least 2 points per output, got {args.resolution}"
        )
    payload = _verification_payload(mech, verify(mech, design, args.resolution))
    if args.json:
        print(json.dumps(payload, indent=2))
    else:
        verdict = "PASS" if payload["passed"] else "FAIL"
        print(
            f"{mech.name}: {verdict}: coverage {100 * payload['coverage']:.1f}% of {payload['cells']} cells; max f_sing {payload['max_f_sing']:.4g} (threshold α₋ {payload['threshold_alpha_minus']:.4g}); min σ FK {payload['min_sigma_fk']:.3g}, BK {payload['min_sigma_bk']:.3g}"
        )
        print(
            "  worst cell "
            + ", ".join(f"{n}={v:.4g}" for n, v in payload["worst_cell"].items())
        )
        if payload["unreached_example"]:
            print(
                "  e.g. unreached "
                + ", ".join(
                    f"{n}={v:.4g}" for n, v in payload["unreached_example"].items()
                )
            )
    return 0 if payload["passed"] else 1


def _cmd_optimize(args) -> int:
    from .._design.optimizer import (
        OptimizerSettings,
    )  # not at module level: it brings pyswarms
    from .._design.run import optimize, write_outputs

    mech = load(args.file)
    if mech.design.size == 0:
        raise InputError(
            f"{args.file}: [[parameters]]: the file declares no design parameters to optimise"
        )
    for flag in ("particles", "iterations", "workers"):
        if getattr(args, flag) < 1:
            raise InputError(
                f"--{flag}: expected a positive integer, got {getattr(args, flag)}"
            )
    if args.seed < 0:
        raise InputError(f"--seed: expected a non-negative integer, got {args.seed}")
    if not (args.tolerance > 0 and 0 <= args.improvement < 1 and args.patience >= 0):
        raise InputError(
            f"--tolerance must be > 0, --improvement in [0, 1), --patience >= 0; got {args.tolerance}, {args.improvement}, {args.patience}"
        )
    settings = OptimizerSettings(
        particles=args.particles,
        iterations=args.iterations,
        seed=args.seed,
        mode=args.mode,
        tolerance=args.tolerance,
        patience=args.patience,
        improvement=args.improvement,
    )

    def report(record: dict) -> None:
        done = record["iteration"] + 1
        elapsed = record["wall_time"]
        remaining = elapsed / done * (settings.iterations - done)
        print(
            f"iteration {record['iteration']:4d}  best f_design {record['best_f_design_overall']:.4e}"
            f" (this iteration {record['best_f_design']:.4e}, regulariser {record['regularizer']:.2e})"
            f"  elapsed {elapsed:6.1f} s  at most {remaining:6.1f} s left",
            file=sys.stderr,
            flush=True,
        )

    run = optimize(
        mech,
        args.out,
        settings,
        resume=args.resume,
        progress=report,
        workers=args.workers,
    )
    print(
        "writing the optimised file, verification and figures ...",
        file=sys.stderr,
        flush=True,
    )
    summary = write_outputs(
        mech, args.out, run, settings, resolution=args.resolution, workers=args.workers
    )
    print(
        json.dumps(
            {
                k: summary[k]
                for k in (
                    "iterations",
                    "f_design",
                    "regularizer",
                    "verified",
                    "initial_verified",
                    "design",
                    "optimized_file",
                )
            },
            indent=2,
        )
    )
    print(
        f"figures: {Path(args.out) / 'spaces_optimized.png'}, {Path(args.out) / 'convergence.png'}, {Path(args.out) / 'mechanism.png'}",
        file=sys.stderr,
    )
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="linkopt",
        description="Singularity-aware design of closed-loop spatial linkages.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    check = sub.add_parser("check", help="validate a mechanism file and summarise it")
    check.add_argument("file")
    check.add_argument("--json", action="store_true", help="machine-readable output")
    check.set_defaults(run=_cmd_check)
    for kind, what, text in (
        ("fk", "motors", "forward kinematics: motor values -> configuration"),
        ("bk", "outputs", "backward kinematics: outputs -> configuration and motors"),
    ):
        cmd = sub.add_parser(kind, help=text)
        cmd.add_argument("file")
        cmd.add_argument(
            f"--{what}",
            required=True,
            help=f"comma-separated {what} (file units, radians), or a CSV file of rows solved as one continuation path",
        )
        cmd.add_argument("--json", action="store_true", help="machine-readable output")
        cmd.set_defaults(run=lambda a, k=kind: _solve_command(a, k))
    evaluate_cmd = sub.add_parser(
        "evaluate", help="IK and adversarial samples, f_design (paper Sec. IV)"
    )
    evaluate_cmd.add_argument("file")
    evaluate_cmd.add_argument(
        "--design",
        help="design values in parameter order (comma-separated), or a mechanism file with the same parameters",
    )
    evaluate_cmd.add_argument(
        "--json", action="store_true", help="machine-readable output"
    )
    evaluate_cmd.set_defaults(run=_cmd_evaluate)
    plot = sub.add_parser(
        "plot", help="motor- and end-effector-space maps and a drawing (PNG)"
    )
    plot.add_argument("file")
    plot.add_argument("--design", help="as for evaluate")
    plot.add_argument("--out", required=True, help="output directory")
    plot.add_argument(
        "--resolution", type=int, default=60, help="grid cells per axis (default 60)"
    )
    plot.add_argument(
        "--label", help="file-name label (default 'initial', or 'design' with --design)"
    )
    plot.set_defaults(run=_cmd_plot)
    verify_cmd = sub.add_parser(
        "verify",
        help="dense check of the whole target range: coverage and singularity distance",
    )
    verify_cmd.add_argument("file")
    verify_cmd.add_argument("--design", help="as for evaluate")
    verify_cmd.add_argument(
        "--resolution",
        type=int,
        help="grid points per output (default 41, or 13 for 3 outputs)",
    )
    verify_cmd.add_argument(
        "--json", action="store_true", help="machine-readable output"
    )
    verify_cmd.set_defaults(run=_cmd_verify)
    opt = sub.add_parser(
        "optimize",
        help="hybrid particle swarm + partial gradient design optimisation (paper Sec. V)",
    )
    opt.add_argument("file")
    opt.add_argument(
        "--out",
        required=True,
        help="run directory (checkpoint, history, optimised file, figures)",
    )
    from .._design.optimizer import OptimizerSettings

    d = OptimizerSettings()
    opt.add_argument(
        "--particles",
        type=int,
        default=d.particles,
        help=f"swarm size (default {d.particles})",
    )
    opt.add_argument(
        "--iterations",
        type=int,
        default=d.iterations,
        help=f"iteration cap (default {d.iterations})",
    )
    opt.add_argument(
        "--seed", type=int, default=d.seed, help=f"random seed (default {d.seed})"
    )
    opt.add_argument(
        "--mode",
        choices=["hybrid", "gradient"],
        default=d.mode,
        help="hybrid PSO + partial gradient (default), or partial gradient only",
    )
    opt.add_argument(
        "--tolerance",
        type=float,
        default=d.tolerance,
        help=f"f_design at or below which a design counts as reaching its range with no singularity (default {d.tolerance:g})",
    )
    opt.add_argument(
        "--patience",
        type=int,
        default=d.patience,
        help=f"stop after this many iterations without improving the returned feasible design (default {d.patience})",
    )
    opt.add_argument(
        "--improvement",
        type=float,
        default=d.improvement,
        help=f"relative drop of the returned design's total that counts as improving (default {d.improvement:g})",
    )
    opt.add_argument(
        "--resume", action="store_true", help="continue the run checkpointed in --out"
    )
    opt.add_argument(
        "--workers",
        type=int,
        default=WORKERS,
        help=f"processes sharing the particles, and the final verifications and plots (default {WORKERS}: one per core, at most 2)",
    )
    opt.add_argument(
        "--resolution",
        type=int,
        default=60,
        help="grid cells per axis of the final plots",
    )
    opt.set_defaults(run=_cmd_optimize)
    _add_arm_commands(sub)
    return parser


def _add_arm_commands(sub) -> None:
    arm = sub.add_parser("arm", help="serial-arm synthesis and co-design")
    arm_sub = arm.add_subparsers(dest="arm_command", required=True)
    for family in (arm_commands, manipulability_commands, trace_commands):
        family.register(arm_sub)


WORKERS = max(1, min(2, os.cpu_count() or 1))


def _join_value_options(argv: list[str]) -> list[str]:
    """``--motors -0.1,0.2`` -> ``--motors=-0.1,0.2`` so negative values are not
    options."""
    joined: list[str] = []
    pending = False
    for token in argv:
        if pending and token.startswith("-"):
            joined[-1] = f"{joined[-1]}={token}"
        else:
            joined.append(token)
        pending = token in ("--motors", "--outputs", "--design")
    return joined


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = _parser().parse_args(_join_value_options(list(argv)))
    try:
        return args.run(args)
    except LinkoptError as err:
        print(f"linkopt: error: {err}", file=sys.stderr)
        return 2
    except (
        BrokenPipeError
    ):  # `linkopt check ... | head`: the reader left, nothing to report
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
