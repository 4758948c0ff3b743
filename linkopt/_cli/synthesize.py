"""``linkopt synthesize FILE [--targets CSV] --out RUN``: path, function or motion
generation on the file's ``[synthesis]`` table.

``RUN`` receives ``optimized.toml`` (the file with the synthesised design, written by
:func:`linkopt.write_design`), ``history.csv`` (one row per iteration),
``summary.json`` (the numbers below, also printed on stdout) and ``synthesis.png``
(the traced curve over the targets, the file's design behind). The summary holds the
RMS and largest distance to the targets, whether every one is within the tolerance,
the least forward ``σ_min`` over the cycle and its margin over ``α₋``, for a planar
four-bar its Grashof class, link ratio and worst transmission angle (``four_bar``),
and the dense cycle sweep's verdict (``verified``, ``defect``: the first defect it
met).

``linkopt synthesize FILE --verify [--design D]`` only sweeps one design (the file's,
or ``D``: values or a file with the same parameters, e.g. ``RUN/optimized.toml``)
densely over its cycle and exits 1 naming the first defect; 0 when there is none.
Progress goes to stderr. A run is not checkpointed (no ``--resume``).
"""

from __future__ import annotations

import csv
import io
import json
import shutil
import sys
from pathlib import Path

from .._design.settings import OptimizerSettings
from .._errors import InputError
from .._folders import output_folder, write_atomic
from .values import design_arg, load

#: Most rows of a swept cycle (``--steps``).
MAX_STEPS = 20_000


def _settings(args) -> OptimizerSettings:
    from .._synth.run import DEFAULT

    return OptimizerSettings(
        particles=args.particles,
        iterations=args.iterations,
        seed=args.seed,
        spread=DEFAULT.spread,
        patience=DEFAULT.patience,
    )


def _check_flags(args) -> None:
    for flag in ("particles", "iterations"):
        if getattr(args, flag) < 1:
            raise InputError(
                f"--{flag}: expected a positive integer, got {getattr(args, flag)}"
            )
    if not 8 <= args.steps <= MAX_STEPS:
        raise InputError(f"--steps: expected 8 to {MAX_STEPS} rows, got {args.steps}")
    if args.out is None and not args.verify:
        raise InputError("--out: a synthesis run needs its run folder")


def _history_csv(history) -> str:
    columns = [k for k in history[0] if k != "best_design"]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(columns)
    for record in history:
        writer.writerow([record[k] for k in columns])
    return out.getvalue()


def _verdict(mech, result) -> dict:
    """The dense cycle sweep's verdict (:mod:`linkopt._synth.cycle`), for the
    summary."""
    from .._synth.run import verify

    report = verify(mech, result)
    return {
        "verified": report.defect is None,
        "defect": report.defect,
        "in_order": bool(report.in_order),
        "largest_jump": float(report.largest_jump),
        "least_sigma_sweep": float(report.least_sigma),
        "least_clearance": report.least_clearance,
    }


def _copy_targets_file(mech, out: Path) -> None:
    """A ``[synthesis].file`` (relative to the file) copied beside the written file,
    so that ``RUN/optimized.toml`` reads the same targets."""
    name = mech.raw.get("synthesis", {}).get("file")
    if isinstance(name, str) and not Path(name).is_absolute():
        source = Path(mech.source).parent / name
        target = out / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)


def _write(mech, result, initial, out: Path) -> dict:
    from .._draw.synthesis import plot_synthesis
    from .._files.writer import write_design

    _copy_targets_file(mech, out)
    write_design(
        mech, result.design, result.alpha_minus, out / "optimized.toml",
        header=f"linkopt synthesize: {result.targets.kind} of {result.targets.name}",
    )  # fmt: skip
    write_atomic(out / "history.csv", _history_csv(result.history))
    plot_synthesis(mech, result, out / "synthesis.png", initial=initial)
    return {"optimized_file": str(out / "optimized.toml")}


def _progress(record: dict) -> None:
    state = "feasible" if record["feasible"] else "not feasible"
    print(
        f"iteration {record['iteration']:4d}  best total {record['best_total']:.4e} "
        f"RMS {record['rms']:.4g} ({state})  elapsed {record['wall_time']:6.1f} s",
        file=sys.stderr,
    )


def _targets(mech, args):
    from .._synth.targets import load_targets

    return load_targets(mech, args.targets)


def _verify_only(args, mech) -> int:
    from .._synth.run import score_design

    targets = _targets(mech, args)
    design = design_arg(mech, args.design)
    result = score_design(mech, targets, design, steps=args.steps)
    summary = {**result.summary(), **_verdict(mech, result)}
    print(json.dumps(summary, indent=2))
    if summary["defect"] is not None:
        print(f"linkopt: verify: {summary['defect']}", file=sys.stderr)
        return 1
    return 0


def run(args) -> int:
    _check_flags(args)
    mech = load(args.file)
    if args.verify:
        return _verify_only(args, mech)
    out = output_folder(args.out)
    targets = _targets(mech, args)
    from .._synth.run import score_design, synthesize

    initial = score_design(mech, targets, steps=args.steps)
    result = synthesize(
        mech, targets, _settings(args), steps=args.steps, progress=_progress
    )
    from .._synth.run import four_bar_summary

    summary = {
        **result.summary(),
        "initial_design": dict(zip(mech.design.names, map(float, mech.design.p0))),
        "initial_rms": initial.rms,
        "four_bar": four_bar_summary(mech, result.design),
        **_verdict(mech, result),
        **_write(mech, result, initial, out),
    }
    write_atomic(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    from .view import write_run_view

    write_run_view(out)
    print(json.dumps(summary, indent=2))
    return 0


def register(subparsers) -> None:
    """Add ``synthesize`` to the ``linkopt`` sub-commands."""
    syn = subparsers.add_parser(
        "synthesize",
        help="path, function or motion generation on the file's [synthesis] table",
    )
    syn.add_argument("file")
    syn.add_argument("--out", help="run directory (design, history, summary, figure)")
    syn.add_argument(
        "--targets", help="a CSV of target rows instead of the table's (docs)"
    )
    syn.add_argument("--seed", type=int, default=0, help="the swarm's seed")
    syn.add_argument("--particles", type=int, default=32)
    syn.add_argument("--iterations", type=int, default=40)
    syn.add_argument(
        "--steps", type=int, default=360, help="rows of the swept cycle (default 360)"
    )
    syn.add_argument(
        "--verify",
        action="store_true",
        help="only sweep one design densely and exit 1 naming its first defect",
    )
    syn.add_argument(
        "--design", help="with --verify: values, or a file with the same parameters"
    )
    syn.set_defaults(run=run)
