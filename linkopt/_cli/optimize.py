"""``linkopt optimize FILE --out DIR``: hybrid particle swarm + partial gradient design
optimisation (paper Sec. V).

``DIR`` holds the run's checkpoint and history (``--resume`` continues it), the
optimised mechanism file, its verification and the figures. Progress lines go to
stderr; the summary (JSON) to stdout.

The command holds the lock on ``DIR`` from before the run starts until its outputs are
written (:func:`linkopt._design.run.locked_run_folder`), so a second ``optimize`` on the
same ``--out`` exits 2 naming the first; a bad ``--out`` or a checkpoint that is not
one ``linkopt optimize`` wrote exits 2 before any optimisation starts.

With ``--scheduler ADDRESS`` each iteration's ``--workers`` particle chunks are
evaluated on a Dask cluster's workers (:mod:`linkopt._design.cluster`; bit-identical to
the local run with the same ``--workers``); a scheduler that does not answer within
``--connect-timeout`` seconds, or Dask not installed, exits 2 with one line.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .._design import ahead
from .._design.settings import OptimizerSettings
from .._errors import InputError
from .._machine import default_workers
from .grids import map_progress
from .values import load

#: The default --workers: one per core of this machine, at most one per 3 GiB of its
#: memory and at most 8 (:func:`linkopt._machine.default_workers`; 2 on 2 cores)
WORKERS = default_workers()
#: Most sample lanes (particles x IK targets) one iteration may evaluate: a thousand
#: times the five-bar's 180, beyond which an iteration takes minutes.
MAX_LANES = 200_000
MAX_WORKERS = 64
#: What the side process of the run's final outputs draws with
#: (:func:`linkopt._design.run.write_outputs`), imported by the optimiser's worker that
#: becomes that process while this one runs the last verification round.
DRAWING = (
    "linkopt._draw.run_folder",
    "linkopt._draw.space_plots",
    "linkopt._draw.animation",
)
#: seconds ``--scheduler`` waits for the scheduler to answer (``--connect-timeout``)
CONNECT_TIMEOUT = 10.0
_SUMMARY_KEYS = (
    "iterations",
    "f_design",
    "regularizer",
    "verified",
    "initial_verified",
    "verification_rounds",
    "capped_samples",
    "design",
    "at_bounds",
    "optimized_file",
)


def check_run_flags(args) -> None:
    """The run options ``optimize`` and ``sweep`` share (all but ``--seed``), checked
    before the file is read."""
    for flag in ("particles", "iterations", "workers"):
        if getattr(args, flag) < 1:
            raise InputError(
                f"--{flag}: expected a positive integer, got {getattr(args, flag)}"
            )
    if args.verify_rounds < 0:
        raise InputError(
            "--verify-rounds: expected a non-negative integer, "
            f"got {args.verify_rounds}"
        )
    if args.workers > MAX_WORKERS:
        raise InputError(
            f"--workers: expected at most {MAX_WORKERS} processes (each holds its own "
            f"JAX runtime), got {args.workers}"
        )
    if args.resolution is not None and args.resolution < 8:  # before the run
        raise InputError(
            f"--resolution: expected at least 8 cells per axis, got {args.resolution}"
        )
    if not (args.tolerance > 0 and 0 <= args.improvement < 1 and args.patience >= 0):
        raise InputError(
            "--tolerance must be > 0, --improvement in [0, 1), --patience >= 0; "
            f"got {args.tolerance}, {args.improvement}, {args.patience}"
        )
    if args.scheduler is not None and not args.connect_timeout > 0:
        raise InputError(
            f"--connect-timeout: expected a positive number of seconds, got "
            f"{args.connect_timeout}"
        )


def check_mechanism(args, mech) -> None:
    """What the run options ask of the file: design parameters, and a swarm whose
    iterations finish (:func:`_check_work`)."""
    if mech.design.size == 0:
        raise InputError(
            f"{args.file}: [[parameters]]: the file declares no design parameters "
            "to optimise"
        )
    _check_work(args, mech)


def round_line(record: dict) -> str:
    """The progress line of a verification round (:mod:`linkopt._design.rounds`),
    numbered as ``summary.json``'s ``verification_rounds`` and ``history.csv``'s
    ``round`` are: round 0 verifies the design of the iterations of round 0."""
    head = (
        f"verification round {record['round']} after {record['iteration']} "
        f"iterations: coverage {record['coverage']:.3f}, max f_sing "
        f"{record['max_f_sing']:.4g} (threshold {record['threshold']:.4g})"
    )
    if record["passed"]:
        return head + ": passed"
    if record["added_targets"]:
        places = "; ".join(
            ", ".join(f"{v:.6g}" for v in t) for t in record["added_targets"]
        )
        return head + f": failed; going on with IK targets added at ({places})"
    return head + ": failed; " + record.get("stopped", "no verification rounds left")


def iteration_line(record: dict) -> str:
    """The progress line of an iteration: the returned design's ``f_design`` and
    regulariser, from the history record that ``history.csv``, ``summary.json`` and
    the convergence plot read (:func:`linkopt._design.optimizer.record_iteration`),
    and this iteration's best particle's ``f_design``."""
    done = record["iteration"] + 1
    elapsed = record["wall_time"]
    remaining = elapsed / done * (record["limit"] - done)
    feasible = "feasible" if record.get("feasible") else "not feasible"
    round_ = f" (round {record['round']})" if record.get("round") else ""
    return (
        f"iteration {record['iteration']:4d}{round_}  best f_design "
        f"{record['best_f_design']:.4e}, regulariser {record['regularizer']:.2e} "
        f"({feasible}; this iteration's best f_design "
        f"{record['iteration_f_design']:.4e})"
        f"  elapsed {elapsed:6.1f} s  at most {remaining:6.1f} s left"
    )


def _check_work(args, mech) -> None:
    """Refuse a swarm whose iterations would not finish on this machine (``MAX_LANES``),
    before any work, with the estimate."""
    from .._design.evaluation import targets

    count = len(targets(mech))
    lanes = args.particles * count
    if lanes > MAX_LANES:
        hours = lanes / 180 / 3600
        raise InputError(
            f"--particles: {args.particles} particles x {count} IK targets make "
            f"{lanes:.3g} sample lanes per iteration (about {hours:.2g} h each on "
            f"2 cores); expected at most {MAX_LANES} lanes"
        )


def _progress():
    """The per-iteration progress line (stderr) and each verification round's."""

    def report(record: dict) -> None:
        if "passed" in record:
            print(round_line(record), file=sys.stderr, flush=True)
            return
        print(iteration_line(record), file=sys.stderr, flush=True)

    return report


def settings_from_args(args, seed: int) -> OptimizerSettings:
    """The run's settings from the flags ``optimize`` and ``sweep`` share."""
    return OptimizerSettings(
        particles=args.particles,
        iterations=args.iterations,
        seed=seed,
        mode=args.mode,
        tolerance=args.tolerance,
        patience=args.patience,
        improvement=args.improvement,
        verify_rounds=args.verify_rounds,
    )


def run_optimize(args) -> int:
    check_run_flags(args)
    if args.seed < 0:
        raise InputError(f"--seed: expected a non-negative integer, got {args.seed}")
    if args.scheduler is None:  # the workers import while this process loads the file
        ahead.start(args.workers, DRAWING)
    try:
        return _run_optimize(args)
    finally:
        ahead.close()


def _run_optimize(args) -> int:
    mech = load(args.file)
    from .._design.run import locked_run_folder, write_outputs
    from .._draw.run_folder import VIEW_FILE, draw_run_figures_and_view

    check_mechanism(args, mech)
    settings = settings_from_args(args, args.seed)
    _initial_ahead(args, mech, settings)
    with locked_run_folder(args.out, args.resume, "--out"):
        run = _optimize(args, mech, settings)
        print(
            "writing the optimised file, verification and figures ...",
            file=sys.stderr,
            flush=True,
        )
        # view.html is drawn beside the figures (draw_run_figures_and_view); an
        # earlier run's would stand for this one's where it could not be
        (Path(args.out) / VIEW_FILE).unlink(missing_ok=True)
        summary = write_outputs(
            mech,
            args.out,
            run,
            settings,
            figures=draw_run_figures_and_view,
            resolution=args.resolution,
            workers=args.workers,
            progress=map_progress(),
        )
        if not (Path(args.out) / VIEW_FILE).is_file():  # written here, or a warning
            from .view import write_run_view

            write_run_view(Path(args.out))
    print(json.dumps({k: summary[k] for k in _SUMMARY_KEYS}, indent=2))
    out = Path(args.out)
    names = ("spaces_optimized.png", "convergence.png", "mechanism.png", "view.html")
    figures = [str(out / name) for name in names if (out / name).is_file()]
    print(f"figures: {', '.join(figures)}", file=sys.stderr)
    from .._design.on_bounds import bounds_line

    line = bounds_line(summary["at_bounds"])
    if line is not None:
        print(f"linkopt: note: {line}", file=sys.stderr)
    if not summary["verified"]:
        print(
            f"linkopt: error: the optimised design does not pass verification (see "
            f"{out / 'verification.json'}); more --iterations or another --seed may "
            "find one that does",
            file=sys.stderr,
        )
        return 1
    return 0


def _initial_ahead(args, mech, settings) -> None:
    """Have the worker process that the optimiser hands back draw the file's design's
    space plot while this one runs the last verification round
    (:func:`linkopt._design.run.initial_figures`; ``write_outputs`` takes it)."""
    if args.scheduler is not None:
        return
    from .._design.run import initial_figures, swarm_rows
    from .._draw.run_folder import draw_run_figures_and_view

    rows = swarm_rows(settings.particles, args.workers)
    figures = draw_run_figures_and_view  # the one write_outputs gets
    ahead.early(initial_figures, mech, rows, args.resolution, figures)


def _optimize(args, mech, settings):
    """The run, on this machine or, with ``--scheduler``, its particle chunks on the
    cluster's workers (:mod:`linkopt._design.cluster`)."""
    from .._design.run import optimize

    run = {"resume": args.resume, "progress": _progress(), "workers": args.workers}
    if args.scheduler is None:
        return optimize(mech, args.out, settings, **run)
    cluster = cluster_module()
    with cluster.connect(args.scheduler, args.connect_timeout) as client:
        return cluster.optimize_on_cluster(client, mech, args.out, settings, **run)


def cluster_module():
    """:mod:`linkopt._design.cluster`, or :class:`~linkopt.InputError` saying how to
    install Dask when it is missing."""
    try:
        from .._design import cluster
    except ModuleNotFoundError as err:
        if err.name is None or err.name.split(".")[0] not in ("distributed", "dask"):
            raise
        raise InputError(
            f"--scheduler needs Dask ({err.name} is not installed): "
            "pip install 'linkopt[cluster]'"
        ) from None
    return cluster


def add_scheduler_options(opt, what: str) -> None:
    """``--scheduler`` and ``--connect-timeout``."""
    opt.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help=(
            f"a Dask scheduler (e.g. tcp://host:8786) whose workers run {what} "
            "(needs pip install 'linkopt[cluster]')"
        ),
    )
    opt.add_argument(
        "--connect-timeout",
        type=float,
        default=CONNECT_TIMEOUT,
        help=f"seconds to wait for --scheduler to answer (default {CONNECT_TIMEOUT:g})",
    )


def register(subparsers) -> None:
    """Add ``optimize`` to the ``linkopt`` sub-commands; its defaults are those of
    :class:`~linkopt.OptimizerSettings`."""
    opt = subparsers.add_parser(
        "optimize",
        help=(
            "hybrid particle swarm + partial gradient design optimisation "
            "(paper Sec. V)"
        ),
    )
    opt.add_argument("file")
    opt.add_argument(
        "--out",
        required=True,
        help="run directory (checkpoint, history, optimised file, figures)",
    )
    settings = OptimizerSettings()
    add_swarm_options(opt, settings)
    add_stopping_options(opt, settings)
    opt.add_argument(
        "--resume", action="store_true", help="continue the run checkpointed in --out"
    )
    opt.add_argument(
        "--workers",
        type=int,
        default=WORKERS,
        help=(
            "processes sharing the particles, and the final verifications and plots "
            f"(default {WORKERS} here: one per core, at most one per 3 GiB of memory "
            "and at most 8); with --scheduler, the "
            "chunks each iteration's particles are split into, as in a local run "
            "with this many workers"
        ),
    )
    add_scheduler_options(opt, "each iteration's particle chunks")
    opt.add_argument(
        "--resolution",
        type=int,
        help=(
            "grid cells per axis of the final plots (default 60 for two outputs, 40 "
            "for the sections of three)"
        ),
    )
    opt.set_defaults(run=run_optimize)


def add_swarm_options(opt, d, seed: bool = True, each: str = "") -> None:
    """``--particles``, ``--iterations`` (the cap ``each`` run), ``--seed`` (with
    ``seed``), ``--mode``; ``d`` holds :class:`~linkopt.OptimizerSettings`'s
    defaults."""
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
        help=f"iteration cap{each} (default {d.iterations})",
    )
    if seed:
        opt.add_argument(
            "--seed", type=int, default=d.seed, help=f"random seed (default {d.seed})"
        )
    opt.add_argument(
        "--mode",
        choices=["hybrid", "gradient"],
        default=d.mode,
        help="hybrid PSO + partial gradient (default), or partial gradient only",
    )


def add_stopping_options(opt, d) -> None:
    """``--tolerance``, ``--patience``, ``--improvement``, ``--verify-rounds``."""
    opt.add_argument(
        "--tolerance",
        type=float,
        default=d.tolerance,
        help=(
            "f_design at or below which a design counts as reaching its range with "
            f"no singularity (default {d.tolerance:g})"
        ),
    )
    opt.add_argument(
        "--patience",
        type=int,
        default=d.patience,
        help=(
            "stop after this many iterations without improving the returned "
            f"feasible design (default {d.patience})"
        ),
    )
    opt.add_argument(
        "--improvement",
        type=float,
        default=d.improvement,
        help=(
            "relative drop of the returned design's total that counts as improving "
            f"(default {d.improvement:g})"
        ),
    )
    opt.add_argument(
        "--verify-rounds",
        type=int,
        default=d.verify_rounds,
        help=(
            "times a run whose design fails verification goes on, with IK targets "
            f"added where it failed (default {d.verify_rounds}; 0: verify only at "
            "the end)"
        ),
    )
