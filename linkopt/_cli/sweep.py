"""``linkopt sweep FILE --seeds 0:64 --out DIR [--scheduler ADDRESS]``: independent
optimisations of one mechanism, one run folder per seed (:mod:`linkopt._design.sweep`).

Without ``--scheduler`` the seeds run one after another in this process, each with
``--workers`` processes sharing its particles (the same runs as ``linkopt optimize``);
with it, each seed is one task on the cluster's workers (one process per run there).
A seed already finished is read back, one with a checkpoint resumes, so a killed sweep
rerun with the same command goes on where it stopped. A line on stderr as each seed
finishes; ``DIR/summary.csv`` and ``DIR/best.toml`` at the end, and the table (JSON)
on stdout. Exit 0 when some run verified, 1 when none did.
"""

from __future__ import annotations

import functools
import json
import sys
import time
from pathlib import Path

from .._design.settings import OptimizerSettings
from .._errors import InputError
from . import optimize as optimize_cli
from .values import load


def _seed_line(row: dict, done: int, total: int, began: float) -> str:
    head = f"seed {row['seed']}: "
    if not row.get("computed", True):
        head += "already finished; "
    return (
        head + f"{row['iterations']} iterations, {row['seconds']:.1f} s, f_design "
        f"{row['f_design']:.3e}, {'verified' if row['verified'] else 'NOT verified'}"
        f"  ({done}/{total} seeds, sweep elapsed {time.perf_counter() - began:.1f} s)"
    )


def _local(args, mech, seeds, report) -> list[dict]:
    from .._design.sweep import run_seed
    from .._draw.run_folder import draw_run_figures

    return [
        report(
            run_seed(
                mech,
                args.out,
                optimize_cli.settings_from_args(args, seed),
                figures=draw_run_figures,
                workers=args.workers,
                resolution=args.resolution,
            )
        )
        for seed in seeds
    ]


def _on_cluster(args, mech, seeds, report) -> list[dict]:
    from .._cache import requested
    from .._design.sweep import finished_row, run_seed
    from .._draw.run_folder import draw_run_figures

    cluster = optimize_cli.cluster_module()
    from distributed import as_completed

    rows = []
    todo = []
    for seed in seeds:  # finished seeds are read here, not sent
        row = finished_row(Path(args.out), seed)
        if row is None:
            todo.append(seed)
        else:
            rows.append(report({**row, "computed": False}))
    with cluster.connect(args.scheduler, args.connect_timeout) as client:
        # run_seed's own keywords bound first: submit's "workers" is Dask's own
        task = functools.partial(
            run_seed,
            figures=draw_run_figures,
            workers=args.workers,
            resolution=args.resolution,
            in_process=True,
            caches=requested(),
        )
        futures = [
            client.submit(
                task,
                mech,
                str(args.out),
                optimize_cli.settings_from_args(args, seed),
                pure=False,
                key=f"linkopt-sweep-seed-{seed}-{time.time_ns()}",
            )
            for seed in todo
        ]
        try:
            for future in as_completed(futures, loop=client.loop):
                rows.append(report(future.result()))
        finally:
            client.cancel(futures)
    return rows


def run_sweep(args) -> int:
    optimize_cli.check_run_flags(args)
    mech = load(args.file)
    from .._design.run import locked_run_folder
    from .._design.sweep import parse_seeds, write_summary

    try:
        seeds = parse_seeds(args.seeds)
    except ValueError as err:
        raise InputError(f"--seeds: expected A:B or a comma list; {err}") from None
    optimize_cli.check_mechanism(args, mech)
    began = time.perf_counter()
    done = []

    def report(row: dict) -> dict:
        done.append(row)
        print(
            _seed_line(row, len(done), len(seeds), began), file=sys.stderr, flush=True
        )
        return row

    with locked_run_folder(args.out, False, "--out") as out:
        args.out = out
        run = _local if args.scheduler is None else _on_cluster
        rows = run(args, mech, seeds, report)
        best = write_summary(out, rows, args.tolerance)
    table = sorted(
        ({k: v for k, v in r.items() if k != "computed"} for r in rows),
        key=lambda r: r["seed"],
    )
    print(json.dumps(table, indent=2))
    if best is None:
        print(
            f"linkopt: error: no run of the sweep passes verification (see "
            f"{out / 'summary.csv'}); no {out / 'best.toml'} written",
            file=sys.stderr,
        )
        return 1
    print(
        f"best verified design: seed {best}, {out / 'best.toml'} (summary: "
        f"{out / 'summary.csv'})",
        file=sys.stderr,
    )
    return 0


def register(subparsers) -> None:
    """Add ``sweep``; its run options are ``optimize``'s."""
    opt = subparsers.add_parser(
        "sweep",
        help="independent optimisations, one per seed, in DIR/seed_NNN (resumable)",
    )
    opt.add_argument("file")
    opt.add_argument(
        "--seeds",
        required=True,
        help="seeds A:B (A to B-1, e.g. 0:64) or a comma list (e.g. 0,3,7)",
    )
    opt.add_argument(
        "--out",
        required=True,
        help="sweep directory: seed_NNN run folders, summary.csv, best.toml",
    )
    settings = OptimizerSettings()
    optimize_cli.add_swarm_options(opt, settings, seed=False, each=" of each run")
    optimize_cli.add_stopping_options(opt, settings)
    opt.add_argument(
        "--workers",
        type=int,
        default=optimize_cli.WORKERS,
        help=(
            "chunks of each iteration's particles (default "
            f"{optimize_cli.WORKERS}), as in optimize: without --scheduler as many "
            "processes share each run; with it each run is one task on one Dask "
            "worker, which evaluates the chunks in turn (the same numbers)"
        ),
    )
    opt.add_argument(
        "--resolution",
        type=int,
        help="grid cells per axis of each run's final plots (as in optimize)",
    )
    optimize_cli.add_scheduler_options(opt, "one optimisation per task")
    opt.set_defaults(run=run_sweep)
