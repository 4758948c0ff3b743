"""Time spent on the outputs a user waits for (issue 20, part 6): the space plot of a
3-motor mechanism, and ``optimize``'s final outputs against its optimisation.

Run: ``.venv/bin/python benchmarks/bench_outputs.py [FILE] [--delta] [--old]
[--optimize] [--defaults] [--run DIR]`` (default FILE ``mechanisms/neck_3dof.toml``;
``--delta``: ``mechanisms/delta.toml``).

Prints wall and CPU seconds (CPU: this process, all threads; the figure to compare on a
shared machine) of

* the evaluation the plot needs and the plot at its default resolution (three outputs:
  40 cells per axis, six 2-D sections solved in their planes from a coarse 3-D seed
  grid, :func:`linkopt._design.maps.sections`);
* with ``--old``, the alternative to the sections: a fine 3-D continuation grid
  (60² x 13 cells) per space, to cut the sections from;
* with ``--optimize``, a 4-particle, 2-iteration optimisation and its
  :func:`linkopt._draw.run_folder.write_outputs` (both designs' verification, the
  figures);
* with ``--defaults``, ``optimize`` at its default settings (20 particles, verification
  rounds, two workers, as the command line runs it) and its ``write_outputs``;
* with ``--run DIR``, ``write_outputs`` (two workers) on a copy of the finished run in
  ``DIR`` (of FILE), its optimisation's wall time read from the checkpoint.

CPU here counts this process and its finished child processes (the workers and the
spawned process of the initial design's outputs). ``--delta --defaults`` and ``--run
DIR`` measure the outputs at the default settings; they take long, so run them on an
idle machine. Baseline: ``BASELINE_PLOT_CPU_S``, ``linkopt plot`` of the neck with one
60 x 60 x 13 continuation grid per space. Writes the steps' seconds to
``benchmarks/results/bench_outputs.json``.

The choices behind these figures are documented where they are made: sections solved
in their planes (:func:`linkopt._design.maps.sections`); the optimised design's space
plot solved with the file's mechanism, so it shares the initial design's programs, and
the last round's verification reused (:func:`linkopt._draw.run_folder.write_outputs`);
verification's singular values as one batch of the grid's shape
(:mod:`linkopt._design.verify`).
"""

from __future__ import annotations

import argparse
import resource
import shutil
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import _results
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
FILE = ROOT / "mechanisms/neck_3dof.toml"
DELTA = ROOT / "mechanisms/delta.toml"
#: CPU seconds of ``linkopt plot mechanisms/neck_3dof.toml`` with a 60 x 60 x 13
#: continuation grid per space instead of the sections (2-core machine).
BASELINE_PLOT_CPU_S = 349.0
#: What :func:`timed` measured, in order: the results file's rows.
STEPS: list[dict] = []


def _cpu() -> float:
    """CPU seconds of this process and its waited-for children."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@contextmanager
def timed(label: str):
    wall, cpu = time.perf_counter(), _cpu()
    yield
    wall, cpu = time.perf_counter() - wall, _cpu() - cpu
    print(f"{label:<44} wall {wall:8.1f} s   CPU {cpu:8.1f} s", flush=True)
    STEPS.append({"step": label, "wall_s": wall, "cpu_s": cpu})


def bench_plot(mech, out: Path) -> None:
    from linkopt._design.evaluation import evaluate
    from linkopt._design.maps import plot_cost, plot_resolution
    from linkopt._draw.space_plots import plot_spaces

    with timed("evaluate (for the plot)"):
        ev = evaluate(mech)
    resolution = plot_resolution(mech)
    cost = plot_cost(mech, resolution)
    label = f"plot_spaces, resolution {resolution} (est. {cost.seconds:.0f} s)"
    with timed(label):
        plot_spaces(mech, ev, out / "spaces.png")


def bench_old_grids(mech, resolution: int = 60) -> None:
    """The fine 3-D grid of each space that the old sections were cut from (the
    windows of :func:`linkopt._draw.plot_maps.section_maps`)."""
    import linkopt
    from linkopt._design import maps
    from linkopt._design.evaluation import evaluate
    from linkopt._draw.plot_maps import plot_windows

    ev = evaluate(mech)
    rest = linkopt.rest_state(mech)
    (m_low, m_high), (o_low, o_high), rest_out = plot_windows(mech, ev, rest, None)
    ik = np.asarray(ev.ik_motors) * mech.motor_scale
    spaces = (
        ("fk", m_low, m_high, np.zeros(3), np.quantile(ik[:, 2], [0, 0.5, 1])),
        (
            "bk",
            o_low,
            o_high,
            rest_out,
            np.linspace(mech.output_min[2], mech.output_max[2], 3),
        ),
    )
    for kind, low, high, start, cuts in spaces:
        third = maps.merged_values(
            low[2], high[2], maps.SECTION_DEPTH, [*cuts, start[2]]
        )
        axes = maps.grid_axes(low[:2], high[:2], resolution) + [third]
        with timed(f"old {kind.upper()} grid {resolution}² x {len(third)}"):
            maps.solve_grid(mech, kind, axes, start, rest, None)


def bench_optimize(mech, out: Path) -> None:
    from linkopt._design.optimizer import OptimizerSettings
    from linkopt._design.run import optimize
    from linkopt._draw.run_folder import write_outputs

    settings = OptimizerSettings(particles=4, iterations=2, seed=0, verify_rounds=0)
    with timed("optimize, 4 particles x 2 iterations"):
        run = optimize(mech, out / "run", settings)
    with timed("write_outputs (verifications, figures)"):
        write_outputs(mech, out / "run", run, settings)


def bench_defaults(mech, out: Path) -> None:
    """``linkopt optimize FILE`` at its default settings, then its outputs."""
    from linkopt._design.optimizer import OptimizerSettings
    from linkopt._design.run import optimize
    from linkopt._draw.run_folder import write_outputs

    settings = OptimizerSettings(seed=0)
    with timed("optimize, default settings, 2 workers"):
        run = optimize(mech, out / "run", settings, workers=2)
    print(f"  {run.iteration} iterations, rounds {[r['passed'] for r in run.rounds]}")
    with timed("write_outputs, 2 workers"):
        write_outputs(mech, out / "run", run, settings, workers=2)


def bench_run(mech, folder: Path, out: Path) -> None:
    """``write_outputs`` on a copy of the finished run in ``folder``."""
    import json

    from linkopt._design.checkpoint import CHECKPOINT
    from linkopt._design.optimizer import OptimizerSettings
    from linkopt._design.run import load_checkpoint
    from linkopt._draw.run_folder import write_outputs

    data = json.loads((folder / CHECKPOINT).read_text())
    settings = OptimizerSettings(**data["settings"])
    copy = out / "run"
    copy.mkdir()
    shutil.copy(folder / CHECKPOINT, copy / CHECKPOINT)
    run = load_checkpoint(copy, mech, settings)
    print(
        f"  run of {run.iteration} iterations, optimisation wall "
        f"{run.history[-1]['wall_time']:.0f} s, rounds "
        f"{[r['passed'] for r in run.rounds]}"
    )
    with timed("write_outputs, 2 workers"):
        write_outputs(mech, copy, run, settings, workers=2)


def main() -> None:
    import linkopt

    parser = argparse.ArgumentParser()
    parser.add_argument("file", nargs="?", default=str(FILE))
    parser.add_argument("--old", action="store_true")
    parser.add_argument("--delta", action="store_true")
    parser.add_argument("--optimize", action="store_true")
    parser.add_argument("--defaults", action="store_true")
    parser.add_argument("--no-plot", action="store_true")
    parser.add_argument("--run", type=Path)
    args = parser.parse_args()
    mech = linkopt.load(DELTA if args.delta else args.file)
    print(f"{mech.name}: {mech.num_outputs} outputs, state size {mech.state_size}")
    print(f"baseline: old plot {BASELINE_PLOT_CPU_S:.0f} CPU s")
    with tempfile.TemporaryDirectory() as tmp:
        if not args.no_plot:
            bench_plot(mech, Path(tmp))
        if args.old:
            bench_old_grids(mech)
        if args.optimize:
            bench_optimize(mech, Path(tmp))
        if args.defaults:
            bench_defaults(mech, Path(tmp))
        if args.run is not None:
            bench_run(mech, args.run, Path(tmp))
    flags = ("no_plot", "old", "delta", "optimize", "defaults")
    options = [f"--{k.replace('_', '-')}" for k in flags if getattr(args, k)]
    _results.write(
        __file__,
        {
            "mechanism": mech.name,
            "outputs": mech.num_outputs,
            "state_size": mech.state_size,
            "options": " ".join(options + ([f"--run {args.run}"] if args.run else [])),
            "baseline_plot_cpu_s": BASELINE_PLOT_CPU_S,
            "steps": STEPS,
        },
    )


if __name__ == "__main__":
    main()
