"""Continuous-path synthesis (paper 002, Table II): the rose, wipe and clean tasks.

Run: ``nice -n 10 .venv/bin/python benchmarks/bench_trace.py [--figures] [--seed S]``

Each case runs in its own process (so each pays its own JIT compilation, from the
persistent cache when warm) and reports wall and CPU seconds, the resulting arm and its
verification, beside the paper's computing times (``PAPER_MIN``; MATLAB fmincon, 3.6 GHz
desktop), and writes them to ``benchmarks/results/bench_trace.json``. Ratios are ours /
paper's. ``--figures`` writes ``figures/trace_*.png`` and ``figures/trace_rose.gif``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import _results

ROOT = Path(__file__).resolve().parent.parent
#: The paper's computing time of each case, minutes: the rose with SV^over and with
#: SV^app, wipe, clean, and the discretised approach on the rose (25 points).
PAPER_MIN = {
    "rose_over": 0.5,
    "rose_app": 2.7,
    "wipe_table": 9.6,
    "clean_table": 7.5,
    "rose_discretised": 6.8,
}
DPI = 100


def _save(fig, path: str) -> None:
    fig.savefig(path, dpi=DPI, bbox_inches="tight")


def _discretised(task, seed: int) -> tuple[dict, object]:
    from linkopt._arms.trace.discrete import compare, discretised_design

    design = discretised_design(task, 25, seed=seed)
    cmp = compare(task, design)
    out = dict(
        lengths=design.lengths.tolist(),
        excursion=cmp.excursion,
        fraction_outside=cmp.fraction_outside,
        verified=cmp.verification.passed,
        failure=(cmp.verification.failures or [None])[0],
    )
    return out, cmp


def _synthesised(name: str, task, seed: int) -> tuple[dict, object]:
    from linkopt._arms.trace.synthesis import TraceSettings, synthesize

    settings = {
        "rose_over": TraceSettings(links=(2,), swept=("over",)),
        "rose_app": TraceSettings(links=(2,), swept=("app",)),
    }.get(name, TraceSettings())
    result = synthesize(task, seed=seed, settings=settings)
    out = dict(success=result.success, solves=len(result.attempts))
    if result.success:
        d, v = result.design, result.verification
        out.update(
            links=d.n_links,
            swept=result.swept,
            lengths=d.lengths.tolist(),
            total=float(d.lengths.sum()),
            verified=v.passed,
            clearance=v.min_clearance,
            samples=sum(len(s.states) for s in v.segments),
        )
    return out, result


def _figures(name: str, task_name: str, task, found) -> None:
    import matplotlib.pyplot as plt

    from linkopt._draw.arms import trace as tp

    fig_dir = f"{ROOT}/figures"
    if name == "rose_discretised":
        _save(
            tp.discretised_figure(task, found), f"{fig_dir}/trace_rose_discretised.png"
        )
        return
    if not found.success:
        return
    d, v = found.design, found.verification
    tag = name if name.startswith("rose") else task_name
    lengths = ", ".join(f"{r:.3g}" for r in d.lengths)
    title = f"{task_name} (SV^{found.swept}): {d.n_links} links, {lengths}"
    _save(
        tp.solution_figure(task, d, v, title=title),
        f"{fig_dir}/trace_{tag}_solution.png",
    )
    _save(tp.swept_figure(task, d, v, found.swept), f"{fig_dir}/trace_{tag}_swept.png")
    if name == "rose_over":
        fig, ax = plt.subplots(figsize=(6, 6))
        tp.draw_task(ax, task)
        tp.set_limits(ax, task, d)
        ax.set_title("task: rose")
        _save(fig, f"{fig_dir}/trace_rose_task.png")
        tp.write_gif(f"{fig_dir}/trace_rose.gif", task, d, v)


def case(name: str, seed: int, figures: bool) -> None:
    """One case, in this (fresh) process: prints ``RESULT {json}``."""
    t0, c0 = time.perf_counter(), time.process_time()
    import linkopt

    linkopt.use_cache()  # float64, and compiled programs kept on disk
    from linkopt._arms.trace.task import load_task

    task_name = "rose" if name.startswith("rose") else name
    task = load_task(f"{ROOT}/tasks/{task_name}.toml")
    if name == "rose_discretised":
        out, found = _discretised(task, seed)
    else:
        out, found = _synthesised(name, task, seed)
    out = {"case": name, **out}
    out["wall_s"], out["cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
    if figures:
        _figures(name, task_name, task, found)
    print("RESULT " + json.dumps(out))


def run_case(name: str, seed: int, figures: bool) -> dict:
    command = [sys.executable, __file__, "--case", name, "--seed", str(seed)]
    proc = subprocess.run(
        command + (["--figures"] if figures else []),
        capture_output=True,
        text=True,
        check=True,
    )
    line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT ") :])


def _describe(name: str, r: dict) -> str:
    lengths = ", ".join(f"{x:.4g}" for x in r.get("lengths", []))
    if name == "rose_discretised":
        check = "passes" if r["verified"] else "fails: " + r["failure"]
        return (
            f"2 links {lengths}; curve up to {r['excursion']:.2g} outside the RS "
            f"({100 * r['fraction_outside']:.1f} %), continuous check {check}"
        )
    if r["success"]:
        return (
            f"{r['links']} links (SV^{r['swept']}) {lengths} = {r['total']:.4g}, "
            f"verified on {r['samples']} samples, clearance {r['clearance']:.3g}, "
            f"{r['solves']} NLP solves"
        )
    return f"no verified design in {r['solves']} NLP solves"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figures", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--case", choices=list(PAPER_MIN), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.case:
        case(args.case, args.seed, args.figures)
        return
    print(
        f"{'case':<17} {'wall s':>7} {'cpu s':>7} {'paper min':>9} {'ratio':>6}  result"
    )
    rows = []
    for name, paper in PAPER_MIN.items():
        r = run_case(name, args.seed, args.figures)
        ratio = r["wall_s"] / (60 * paper)
        print(
            f"{name:<17} {r['wall_s']:7.1f} {r['cpu_s']:7.1f} {paper:9.1f} "
            f"{ratio:6.3f}  {_describe(name, r)}",
            flush=True,
        )
        rows.append(
            {
                "case": name,
                "wall_s": r["wall_s"],
                "cpu_s": r["cpu_s"],
                "paper_min": paper,
                "ours_over_paper": ratio,
                "verified": r.get("verified", False),
                "result": _describe(name, r),
            }
        )
    _results.write(__file__, {"seed": args.seed, "cases": rows})


if __name__ == "__main__":
    main()
