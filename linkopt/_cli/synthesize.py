"""``linkopt synthesize FILE [--targets CSV] --out RUN``: path, function or motion
generation on the file's ``[synthesis]`` table.

``RUN`` receives, as ``linkopt optimize`` writes its run folder: ``optimized.toml``
(the file with the synthesised design, written by :func:`linkopt.write_design`),
``history.csv`` (one row per iteration), ``summary.json`` (the numbers below, also
printed on stdout), ``synthesis.png`` (the traced curve over the targets, the file's
design behind), ``synthesis.gif`` (the design moving through its cycle, the traced
point's path growing over the targets), the exports of ``--export`` (default
``mjcf``: ``optimized.xml``, as ``optimize`` writes; also ``urdf``, ``stl``, ``glb``,
``dxf``, ``svg``, with ``linkopt export``'s checks made before any work),
``view.html`` and ``checkpoint.json`` (:mod:`.synth_checkpoint`, replaced after
every iteration; ``--resume`` continues the run exactly). The summary holds the RMS
and largest distance to the targets, whether every one is within the tolerance, the
least forward ``σ_min`` over the cycle and its margin over ``α₋``, for a planar
four-bar its Grashof class, link ratio and worst transmission angle (``four_bar``),
and the dense cycle sweep's verdict (``verified``, ``defect``: the first defect it
met).

``linkopt synthesize FILE --verify [--design D]`` only sweeps one design (the file's,
or ``D``: values or a file with the same parameters, e.g. ``RUN/optimized.toml``)
densely over its cycle and exits 1 naming the first defect; 0 when there is none.
Progress (each iteration, then each stage of the outputs) goes to stderr. The run
folder is locked while the command runs, as ``optimize``'s is.
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
    if args.resume and args.verify:
        raise InputError("--resume: not with --verify (nothing to resume)")
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


#: ``--export`` formats and the run folder's file for each (``linkopt export``'s
#: formats but stl, whose one file per body ``linkopt export`` writes on its own).
EXPORT_NAMES = {
    "mjcf": "optimized.xml",
    "urdf": "optimized.urdf",
    "glb": "optimized.glb",
    "dxf": "optimized.dxf",
    "svg": "optimized.svg",
}


def export_formats(text: str) -> tuple[str, ...]:
    """``--export``: a comma-separated list of :data:`EXPORT_NAMES` formats, or
    ``none``."""
    if text.strip().lower() == "none":
        return ()
    formats = tuple(f.strip().lower() for f in text.split(",") if f.strip())
    bad = [f for f in formats if f not in EXPORT_NAMES]
    if bad or not formats:
        raise InputError(
            f"--export: expected formats among {','.join(EXPORT_NAMES)} (comma-"
            f"separated) or none, got {text!r}"
        )
    return tuple(dict.fromkeys(formats))


def check_exports(mech, formats) -> None:
    """Each format can be written for ``mech``, before any work: the checks of
    ``linkopt export`` (file units, a closed loop as URDF, a spatial mechanism as
    DXF or SVG, ezdxf installed)."""
    from .._export.sheet import check_planar, require_ezdxf
    from .._export.tree import metres_per_unit
    from .._export.urdf import check_open_chain

    if formats:
        metres_per_unit(mech)
    if "urdf" in formats:
        check_open_chain(mech)
    if "dxf" in formats or "svg" in formats:
        check_planar(mech, mech.design.p0)
    if "dxf" in formats:
        require_ezdxf()


def _exports(mech, design, formats, out: Path) -> dict:
    """The design in each format (``linkopt export``'s writers, default thickness)."""
    from .._export import meshes, mjcf, sheet, urdf

    writers = {
        "mjcf": mjcf.export_mjcf,
        "urdf": urdf.export_urdf,
        "glb": meshes.export_glb,
        "dxf": sheet.export_dxf,
        "svg": sheet.export_svg,
    }
    written = {}
    for fmt in formats:
        writers[fmt](mech, out / EXPORT_NAMES[fmt], design)
        written[fmt] = str(out / EXPORT_NAMES[fmt])
    return written


def _stage(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _write(mech, result, initial, out: Path, formats=()) -> dict:
    from .._draw.synthesis import animate_synthesis, plot_synthesis
    from .._files.writer import write_design

    _stage("writing the synthesised file, figure, animation and exports ...")
    _copy_targets_file(mech, out)
    write_design(
        mech, result.design, result.alpha_minus, out / "optimized.toml",
        header=f"linkopt synthesize: {result.targets.kind} of {result.targets.name}",
    )  # fmt: skip
    write_atomic(out / "history.csv", _history_csv(result.history))
    plot_synthesis(mech, result, out / "synthesis.png", initial=initial)
    animate_synthesis(mech, result, out / "synthesis.gif")
    return {
        "optimized_file": str(out / "optimized.toml"),
        "animation": str(out / "synthesis.gif"),
        "exports": _exports(mech, result.design, formats, out),
    }


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


def _start(args, mech, targets, settings, out: Path):
    """The run to continue (``--resume``: the checkpoint, checked in full) or None;
    a folder holding a run is refused without ``--resume``."""
    from . import synth_checkpoint

    if args.resume:
        return synth_checkpoint.load(out, mech, settings, args.steps, targets)
    if (out / synth_checkpoint.CHECKPOINT).exists():
        raise InputError(
            f"{out}: already holds a synthesis run; pass --resume to continue it, or "
            "choose another --out"
        )
    return None


def run(args) -> int:
    _check_flags(args)
    mech = load(args.file)
    if args.verify:
        return _verify_only(args, mech)
    from .._design.run import locked_run_folder

    with locked_run_folder(args.out, args.resume, "--out") as out:
        return _synthesize(args, mech, output_folder(out))


def _synthesize(args, mech, out: Path) -> int:
    from . import synth_checkpoint

    formats = export_formats(args.export)
    check_exports(mech, formats)
    targets = _targets(mech, args)
    settings = _settings(args)
    resume = _start(args, mech, targets, settings, out)
    from .._synth.run import score_design, synthesize

    _stage("scoring the file's design over its cycle (compiles once per structure) ...")
    initial = score_design(mech, targets, steps=args.steps)
    if resume is not None:
        _stage(f"resuming {out} after {resume.iteration} finished iterations")
    result = synthesize(
        mech, targets, settings, steps=args.steps, progress=_progress, resume=resume,
        checkpoint=lambda state: synth_checkpoint.save(
            out, state, mech, settings, args.steps, targets
        ),
    )  # fmt: skip
    from .._synth.run import four_bar_summary

    _stage("sweeping the synthesised design's cycle densely ...")
    summary = {
        **result.summary(),
        "initial_design": dict(zip(mech.design.names, map(float, mech.design.p0))),
        "initial_rms": initial.rms,
        "four_bar": four_bar_summary(mech, result.design),
        **_verdict(mech, result),
        **_write(mech, result, initial, out, formats),
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
    syn.add_argument(
        "--out",
        help="run directory (design, history, summary, figure, animation, exports, "
        "checkpoint)",
    )
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
        "--export",
        default="mjcf",
        help=(
            "formats of the synthesised design written beside it, comma-separated: "
            f"{','.join(EXPORT_NAMES)}, or none (default mjcf, optimized.xml, as "
            "optimize writes)"
        ),
    )
    syn.add_argument(
        "--resume",
        action="store_true",
        help="continue the run checkpointed in --out (same file, targets and flags)",
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
