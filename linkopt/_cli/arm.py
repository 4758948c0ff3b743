"""``linkopt arm design`` and ``linkopt arm simplify``: solve an arm task file, write
the results.

``DIR`` receives, per solved arm (prefix ``""`` for ``design``, ``stage<k>_`` for
``simplify``): ``design.toml`` (the arm at its optimised design, a mechanism file every
command accepts), ``waypoints.csv`` (joint angles, tool position and tip axis per
waypoint, target marks), ``torques.csv`` (static torques per waypoint),
``constraints.json`` (every constraint value ``g``, ≤ 0 is satisfied), ``summary.json``
and the figures (``arm.png``, and for ``simplify`` ``elimination.png``). Progress lines
go to stderr.

The command holds the lock on ``DIR`` (:mod:`linkopt._folders`) from before the solve
until its files are written: a second command on the same ``DIR`` exits 2 naming the
first. The files are written to a staging folder inside ``DIR`` and moved in together
once all are written, ``summary.json`` last; a command that fails or is killed before
that leaves none of them (and ``DIR``'s earlier files as they were).

Exit status: 0 when the returned arm is feasible (``design``: the best start;
``simplify``: the smallest feasible stage), 1 when it is not (the files are still
written), 2 on bad input (one ``linkopt: error: ...`` line on stderr).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._arms import checks
from .._errors import InputError
from .._folders import run_folder, staged

if TYPE_CHECKING:
    from .._arms.codesign import multistart, nlp


def _progress(solution: multistart.ArmSolution) -> None:
    state = (
        "feasible"
        if solution.feasible
        else f"infeasible (max g {solution.max_violation:.2e})"
    )
    print(
        f"start {solution.start}: {state}, objective {solution.objective:.4g}, "
        f"{solution.iterations} iterations, {solution.seconds:.1f} s",
        file=sys.stderr,
        flush=True,
    )


def _rows_table(header: list[str], rows: np.ndarray) -> str:
    return (
        ",".join(header)
        + "\n"
        + "\n".join(",".join(f"{v:.9g}" for v in row) for row in rows)
        + "\n"
    )


def _feasible(solution: multistart.ArmSolution) -> str:
    return "feasible" if solution.feasible else "infeasible"


def write_solution(
    problem: nlp.Problem, solution: multistart.ArmSolution, out: Path, prefix: str = ""
) -> dict:
    """Write one solved arm (module docstring); returns its summary dictionary."""
    from .._arms.codesign import nlp
    from .._draw.arms.codesign import plot_solution

    arm = problem.arm
    z = np.concatenate([solution.theta.ravel(), solution.design])
    report = nlp.waypoint_report(problem, z)
    _write_design(arm, solution, out / f"{prefix}design.toml")
    _write_tables(problem, solution, report, out, prefix)
    _write_constraints(problem, solution, z, report, out / f"{prefix}constraints.json")
    plot_solution(
        problem,
        solution,
        out / f"{prefix}arm.png",
        title=(
            f"{arm.name}: objective {solution.objective:.4g}, {_feasible(solution)}"
        ),
    )
    return {
        "joints": arm.num_joints,
        "design": dict(zip(arm.design_names, map(float, solution.design))),
        "feasible": solution.feasible,
        "max_violation": solution.max_violation,
        "objective": solution.objective,
        "parts": solution.parts,
        "iterations": solution.iterations,
        "seconds": solution.seconds,
        "max_abs_torque": float(np.abs(report["torque"]).max()),
    }


def _write_design(arm, solution: multistart.ArmSolution, path: Path) -> None:
    """The arm at its optimised design as a mechanism file, the design in a header."""
    from .._arms.codesign.model import mechanism_definition
    from .._files.writer import dumps

    header = (
        f"{arm.name}: optimised by linkopt arm (paper 000), "
        f"feasible = {solution.feasible}\n"
        + "\n".join(f"{n} = {v:.9g}" for n, v in zip(arm.design_names, solution.design))
    )
    text = "".join(f"# {line}\n" for line in header.splitlines()) + dumps(
        mechanism_definition(arm, solution.design)
    )
    path.write_text(text, encoding="utf-8")


def _write_tables(
    problem: nlp.Problem,
    solution: multistart.ArmSolution,
    report: dict,
    out: Path,
    prefix: str,
) -> None:
    """``waypoints.csv`` and ``torques.csv``."""
    arm = problem.arm
    joints = [f"theta{k + 1}" for k in range(arm.num_joints)]
    target = np.full(problem.num_waypoints, -1.0)
    target[problem.target_waypoints] = np.arange(len(problem.target_waypoints))
    table = np.column_stack(
        [
            np.arange(problem.num_waypoints),
            target,
            solution.theta,
            report["tip"],
            report["axis"],
        ]
    )
    (out / f"{prefix}waypoints.csv").write_text(
        _rows_table(
            ["waypoint", "target"]
            + joints
            + ["x", "y", "z", "axis_x", "axis_y", "axis_z"],
            table,
        ),
        encoding="utf-8",
    )
    torques = np.column_stack([np.arange(problem.num_waypoints), report["torque"]])
    (out / f"{prefix}torques.csv").write_text(
        _rows_table(
            ["waypoint"] + [f"tau{k + 1}" for k in range(arm.num_joints)], torques
        ),
        encoding="utf-8",
    )


def _write_constraints(
    problem: nlp.Problem, solution: multistart.ArmSolution, z, report: dict, path: Path
) -> None:
    from .._arms.codesign import nlp

    _, _, g, _ = nlp.evaluate(problem, z)
    path.write_text(
        json.dumps(
            {
                "max_g": solution.max_violation,
                "g": g.tolist(),
                "torque_limit": problem.arm.torque_limit,
                "max_abs_torque": float(np.abs(report["torque"]).max()),
            },
            indent=1,
        ),
        encoding="utf-8",
    )


#: Limits of the flags: ``--starts`` as the task's ``[solver] starts``; each worker is
#: a process holding its own JAX runtime (hundreds of MB).
MAX_WORKERS = 64


def _check_arguments(args) -> None:
    if args.starts is not None:
        from .._arms.codesign.task import LIMITS

        checks.count(args.starts, "--starts", maximum=LIMITS["solver"]["starts"])
    if args.seed is not None:
        checks.seed(args.seed, "--seed")
    checks.count(args.workers, "--workers", maximum=MAX_WORKERS)
    if hasattr(args, "min_joints"):
        checks.count(args.min_joints, "--min-joints")


def _task(args):
    """The checked arguments' task file, loaded: all input is checked here."""
    _check_arguments(args)
    from .._arms.codesign.task import load_task

    task = load_task(args.task)
    joints = task.arm.num_joints
    if hasattr(args, "min_joints") and args.min_joints > joints:
        raise InputError(
            f"--min-joints: expected at most the task's {joints} joints, got "
            f"{args.min_joints}"
        )
    return task


def _solve(args, task):
    from .._arms.codesign import multistart, nlp

    problem = nlp.prepare(task)
    print(
        f"{task.name}: {task.arm.num_joints} joints, {task.arm.num_design} design "
        f"parameters, {len(task.targets)} targets, {problem.num_waypoints} waypoints",
        file=sys.stderr,
        flush=True,
    )
    started = time.perf_counter()
    best, runs = multistart.solve(
        problem,
        starts=args.starts,
        seed=args.seed,
        workers=args.workers,
        progress=_progress,
    )
    return problem, best, runs, time.perf_counter() - started


def _starts_summary(runs) -> list[dict]:
    return [
        {
            "start": r.start,
            "feasible": r.feasible,
            "objective": r.objective,
            "max_violation": r.max_violation,
            "seconds": r.seconds,
            "message": r.message,
        }
        for r in runs
    ]


def run_design(args) -> int:
    task = _task(args)
    with run_folder(args.out) as out:
        problem, best, runs, seconds = _solve(args, task)
        with staged(out, marker="summary.json") as stage:
            summary = write_solution(problem, best, stage)
            summary.update(
                {
                    "task": str(args.task),
                    "best_start": best.start,
                    "wall_seconds": seconds,
                    "starts": _starts_summary(runs),
                }
            )
            (stage / "summary.json").write_text(
                json.dumps(summary, indent=1), encoding="utf-8"
            )
    state = "feasible" if best.feasible else "INFEASIBLE"
    print(
        f"best: start {best.start}, {state}, objective {best.objective:.4g}; "
        f"{sum(r.feasible for r in runs)}/{len(runs)} starts feasible; "
        f"{seconds:.0f} s; written to {out}"
    )
    return 0 if best.feasible else 1


def _stage_progress(stage) -> None:
    e = stage.elimination
    deltas = ", ".join(f"{d:.3g}" for d in stage.deltas)
    print(
        f"merged joints {e.candidate + 1}+{e.candidate + 2} (δ of candidates: "
        f"{deltas}); re-optimised {stage.problem.arm.num_joints}-joint arm: "
        f"{_feasible(stage.solution)}",
        file=sys.stderr,
        flush=True,
    )


def _write_stages(stages, out: Path) -> list[dict]:
    """Each stage's files (prefix ``stage<k>_``); returns their summaries."""
    summaries = []
    for k, stage in enumerate(stages):
        entry = write_solution(stage.problem, stage.solution, out, f"stage{k}_")
        if stage.elimination is not None:
            entry.update(
                {
                    "merged": [
                        stage.elimination.candidate + 1,
                        stage.elimination.candidate + 2,
                    ],
                    "delta": stage.elimination.delta,
                    "candidate_deltas": list(stage.deltas),
                }
            )
        summaries.append(entry)
    return summaries


def run_simplify(args) -> int:
    from .._arms.codesign import elimination

    task = _task(args)
    with run_folder(args.out) as out:
        problem, best, runs, _ = _solve(args, task)
        stages = (
            elimination.simplify(
                problem, best, min_joints=args.min_joints, progress=_stage_progress
            )
            if best.feasible
            else [elimination.Stage(problem, best, None)]
        )
        final = max((k for k, s in enumerate(stages) if s.solution.feasible), default=0)
        earlier = stage_files(out)  # an earlier run's stages that this one lacks
        with staged(out, marker="summary.json", obsolete=earlier) as stage:
            _write_simplified(args, stages, final, runs, stage)
    joints = " -> ".join(str(s.problem.arm.num_joints) for s in stages)
    print(
        f"joints: {joints}; smallest feasible arm: "
        f"{stages[final].problem.arm.num_joints} joints (stage {final}); "
        f"written to {out}"
    )
    return 0 if stages[final].solution.feasible else 1


def stage_files(folder: Path) -> list[str]:
    """Names of the ``stage<k>_*`` files in ``folder`` (an earlier ``simplify``'s)."""
    return sorted(
        p.name for p in folder.glob("stage*_*") if p.name[5:].split("_")[0].isdigit()
    )


def _write_simplified(args, stages, final: int, runs, out: Path) -> None:
    """Every stage's files, ``elimination.png`` and ``summary.json``."""
    from .._draw.arms.codesign import plot_stages

    summaries = _write_stages(stages, out)
    plot_stages(stages, out / "elimination.png")
    (out / "summary.json").write_text(
        json.dumps(
            {
                "task": str(args.task),
                "stages": summaries,
                "final_stage": final,
                "starts": _starts_summary(runs),
            },
            indent=1,
        ),
        encoding="utf-8",
    )


def _common(parser) -> None:
    parser.add_argument("task", help="arm task file (TOML)")
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument(
        "--starts",
        type=int,
        default=None,
        help="random initial seeds (default: the task's [solver] starts)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of the first start (default: the task's [solver] seed)",
    )
    parser.add_argument(
        "--workers", type=int, default=1, help="processes solving starts in parallel"
    )


def register(arm_subparsers) -> None:
    """Add ``design`` and ``simplify`` to the ``linkopt arm`` sub-commands."""
    design = arm_subparsers.add_parser(
        "design",
        help="co-design an arm and its trajectory for a task (paper 000, eq. 1-8)",
    )
    _common(design)
    design.set_defaults(run=run_design)
    simplify = arm_subparsers.add_parser(
        "simplify", help="design, then eliminate joints and re-optimise (Algorithm 1)"
    )
    _common(simplify)
    simplify.add_argument(
        "--min-joints", type=int, default=1, help="stop at this many joints"
    )
    simplify.set_defaults(run=run_simplify)
