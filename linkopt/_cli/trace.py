"""``linkopt arm trace TASK --out DIR``: continuous-path synthesis of a planar arm
(paper 002).

Writes ``DIR/result.json`` (design, per-primitive critical states and joint-angle
trajectories, verification figures, every NLP attempt), ``DIR/arm.toml`` (the arm as a
mechanism file that ``linkopt check`` accepts), ``DIR/<task>_task.png``,
``<task>_solution.png``, ``<task>_swept.png``, ``<task>.gif`` and, with
``--discretised N``, the comparison with an N-point discretisation. ``<task>`` is the
task's name with every character other than letters, digits, ``.``, ``_`` and ``-``
replaced by ``_`` (leading dots dropped). When no design is found only ``result.json``
and ``<task>_task.png`` (the task alone) are written, plus the discretised comparison if
one was asked for and found (and an ``arm.toml`` of an earlier run in ``DIR`` is
removed). The command holds the lock on ``DIR`` (:mod:`linkopt._folders`) from before
the synthesis until its files are written: a second command on the same ``DIR`` exits 2
naming the first. The files are written to a staging folder inside ``DIR`` and moved in
together once all are written, ``result.json`` last; a command that fails or is killed
before that leaves none of them. Progress goes to stderr; exit status 0 with a verified
design, 1 when none was found, 2 on bad input.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from .._arms import checks
from .._arms.trace.settings import TraceSettings
from .._errors import InputError
from .._folders import run_folder, staged
from .options import Option, add_options, settings_of

#: The options that set :class:`~linkopt.arms.trace.TraceSettings` fields.
OPTIONS = (
    Option("--restarts", "restarts", "initial guesses per stage"),
    Option(
        "--best-of",
        "best_of",
        "collect K verified designs in the first successful stage and keep the "
        "shortest",
        metavar="K",
    ),
)


def register(arm_subparsers) -> None:
    p = arm_subparsers.add_parser(
        "trace",
        help=(
            "synthesise a 2-/3-link planar arm tracing a continuous path around "
            "obstacles"
        ),
    )
    p.add_argument(
        "task",
        help="task file (TOML: primitives, obstacles, base_regions, link diameter)",
    )
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--seed", type=int, default=0, help="seed of the initial guesses (default 0)"
    )
    add_options(p, TraceSettings(), OPTIONS)
    p.add_argument(
        "--discretised",
        type=int,
        default=0,
        metavar="N",
        help=(
            "also synthesise from N equidistant points and show where the curve "
            "leaves its reachable space"
        ),
    )
    p.add_argument("--no-gif", action="store_true", help="skip the animation")
    p.set_defaults(run=run)


#: Limits of the flags (a 2-core machine: each restart solves up to 8 NLPs, each
#: discretised point adds constraints to a dense SLSQP problem).
MAX_RESTARTS = 1000
MAX_BEST_OF = 100
MAX_DISCRETISED = 10_000


def _check_flags(args) -> None:
    """Every flag meaningful and within its limit, before any work."""
    checks.seed(args.seed, "--seed")
    checks.count(args.restarts, "--restarts", maximum=MAX_RESTARTS)
    checks.count(args.best_of, "--best-of", maximum=MAX_BEST_OF)
    if args.discretised < 0 or args.discretised == 1:
        raise InputError(
            "--discretised: expected 0 (off) or at least 2 points, "
            f"got {args.discretised}"
        )
    checks.count(args.discretised, "--discretised", minimum=0, maximum=MAX_DISCRETISED)


def _say(msg: str) -> None:
    print(f"linkopt arm trace: {msg}", file=sys.stderr, flush=True)


def run(args) -> int:
    from .._arms.trace.task import load_task

    _check_flags(args)
    task = load_task(args.task)
    from .._arms.trace.synthesis import synthesize

    with run_folder(args.out) as out:
        result = synthesize(
            task,
            seed=args.seed,
            settings=settings_of(args, TraceSettings, OPTIONS),
            progress=_say,
        )
        # without a design, an arm.toml of an earlier run must not outlive its result
        stale = () if result.success else ("arm.toml",)
        with staged(out, marker="result.json", obsolete=stale) as stage:
            _write(task, result, args, stage)
    _summary(result, out)
    return 0 if result.success else 1


def _write(task, result, args, out: Path) -> None:
    """The figures, ``arm.toml`` with a design, and ``result.json``."""
    from .._arms.trace.export import mechanism_text, result_dict

    payload = result_dict(result)
    figures = _figures(task, result, out, not args.no_gif)
    if args.discretised:
        payload["discretised"] = _discretised(task, args, out, figures)
    payload["figures"] = figures
    if result.success:
        (out / "arm.toml").write_text(mechanism_text(result), encoding="utf-8")
        payload["mechanism"] = "arm.toml"
    (out / "result.json").write_text(json.dumps(payload, indent=2), encoding="utf-8")


def file_stem(name: str) -> str:
    """The task name made safe as a file-name stem (module docstring)."""
    return re.sub(r"[^A-Za-z0-9._-]", "_", name).lstrip(".") or "task"


def _figures(task, result, out: Path, gif: bool) -> list[str]:
    """The task figure always; the solution, swept-area figures and GIF with a
    design."""

    from .._draw.arms import trace as tp
    from .._draw.figures import subplots

    stem, names = file_stem(task.name), []
    fig, ax = subplots(figsize=(6, 6))
    tp.draw_task(ax, task)
    tp.set_limits(ax, task, result.design)
    ax.set_title(f"task {task.name}")
    figures = [("task", lambda: fig)]
    if result.success:
        figures += [
            (
                "solution",
                lambda: tp.solution_figure(task, result.design, result.verification),
            ),
            (
                "swept",
                lambda: tp.swept_figure(
                    task, result.design, result.verification, result.swept
                ),
            ),
        ]
    for name, make in figures:
        figure = make()
        figure.savefig(out / f"{stem}_{name}.png", dpi=110, bbox_inches="tight")
        names.append(f"{stem}_{name}.png")
    if gif and result.success:
        tp.write_gif(out / f"{stem}.gif", task, result.design, result.verification)
        names.append(f"{stem}.gif")
    return names


def _discretised(task, args, out: Path, figures: list[str]) -> dict:

    from .._arms.trace.discrete import compare, discretised_design
    from .._arms.trace.export import design_dict
    from .._draw.arms import trace as tp

    _say(f"discretised approach: {args.discretised} equidistant points")
    design = discretised_design(
        task, args.discretised, seed=args.seed, restarts=args.restarts
    )
    if design is None:
        return {"points": args.discretised, "found": False}
    cmp = compare(task, design, args.discretised)
    fig = tp.discretised_figure(task, cmp)
    fig.savefig(
        out / f"{file_stem(task.name)}_discretised.png", dpi=110, bbox_inches="tight"
    )
    figures.append(f"{file_stem(task.name)}_discretised.png")
    return {
        "points": args.discretised,
        "found": True,
        **design_dict(design),
        "max_excursion": cmp.excursion,
        "fraction_outside": cmp.fraction_outside,
        "continuous_verification_passed": cmp.verification.passed,
        "continuous_verification_failures": cmp.verification.failures[:10],
    }


def _summary(result, out: Path) -> None:
    if not result.success:
        print(
            f"{result.task.name}: no verified design after {len(result.attempts)} "
            f"NLP solves ({result.seconds:.1f} s); see {out / 'result.json'}"
        )
        return
    d, v = result.design, result.verification
    lengths = ", ".join(f"{r:.4g}" for r in d.lengths)
    elbow = "up" if d.sigma > 0 else "down"
    samples = sum(len(s.states) for s in v.segments)
    print(
        f"{result.task.name}: {d.n_links} links (SV^{result.swept}), lengths "
        f"{lengths}, total {d.lengths.sum():.4g}, elbow {elbow}, "
        f"base ({d.base[0]:.4g}, {d.base[1]:.4g})"
    )
    print(
        f"  verified: min clearance {v.min_clearance:.3g}, min self-distance "
        f"{v.min_self_distance:.3g}, reach margin {v.min_reach_margin:.3g}, "
        f"{samples} samples; {result.seconds:.1f} s"
    )
    print(f"  wrote {out / 'result.json'}, {out / 'arm.toml'}")
