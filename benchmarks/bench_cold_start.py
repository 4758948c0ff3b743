"""A new user's first commands, each from a cold compilation cache: how long until
``linkopt evaluate`` answers for a mechanism, and for a second mechanism of the same
topology once the first has filled the cache.

Run: ``.venv/bin/python benchmarks/bench_cold_start.py [--repeat N] [--before TREE]``.

Each case runs ``linkopt evaluate FILE --json`` in a fresh process. "cold" cases start
from an empty cache folder (``LINKOPT_CACHE_DIR`` a new temporary one); a "after X"
case shares the cache that ``X`` (run just before it, not timed) filled. The figures
are printed against the targets of issues 31 and 43 (2-core machine, empty cache) and
written to ``benchmarks/results/bench_cold_start.json`` with the date, machine and
commit. ``--before TREE`` also runs every case with another checkout's code
(``PYTHONPATH=TREE``, the same mechanism files), alternating with this one's in each
repeat so that a change of load affects both alike, and prints the after/before
ratios; both must give the same ``f_design`` to 1e-9 relative (1e-12 absolute below
1e-3: a design whose samples are all far from singularities has an ``f_design`` of
1e-20 or so, rounding alone).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _results

ROOT = Path(__file__).resolve().parent.parent
LINKOPT = [sys.executable, "-m", "linkopt"]
#: A file made from ``five_bar.toml`` (:func:`_retuned`): the same linkage with other
#: ``[evaluation]`` and ``[solver]`` numbers, as a user tuning a run writes it.
RETUNED = "five_bar_retuned.toml"
#: (label, file, the file run first on the same cache or None, target in seconds)
CASES = (
    ("five-bar cold", "mechanisms/five_bar.toml", None, 8.0),
    ("delta cold", "mechanisms/delta.toml", None, 15.0),
    ("stewart cold", "mechanisms/stewart.toml", None, 15.0),
    ("delta_deep_box after delta", "mechanisms/delta_deep_box.toml",
     "mechanisms/delta.toml", 5.0),
    ("stewart_wide_tilt after stewart", "mechanisms/stewart_wide_tilt.toml",
     "mechanisms/stewart.toml", 5.0),
    ("five-bar retuned after five-bar", RETUNED, "mechanisms/five_bar.toml", 5.0),
)  # fmt: skip


def _retuned(folder: Path) -> Path:
    """:data:`RETUNED`, written into ``folder``."""
    text = (ROOT / "mechanisms/five_bar.toml").read_text()
    old = "alpha_factor = 3.0\n"
    assert old in text, "five_bar.toml changed: update _retuned"
    new = (
        "alpha_factor = 2.5\nmotion_weight = 0.5\nrange_weight = 2.0\n"
        "max_step = 0.08\nik_iterations = 30\n\n"
        "[solver]\nmax_iterations = 50\ntolerance = 1e-11\n"
    )
    path = folder / RETUNED
    path.write_text(text.replace(old, new))
    return path


def _evaluate(path: str, cache: Path, tree: Path) -> tuple[float, dict]:
    """One ``linkopt evaluate`` of ``tree``'s code (run in ``tree``, so that its
    package is the one imported) on this checkout's file ``path``."""
    env = dict(os.environ, LINKOPT_CACHE_DIR=str(cache), PYTHONPATH=str(tree))
    if path == RETUNED:
        path = _retuned(cache)
    start = time.perf_counter()
    run = subprocess.run(
        [*LINKOPT, "evaluate", str(ROOT / path), "--json"],
        env=env, cwd=tree, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return time.perf_counter() - start, json.loads(run.stdout)


def _case(path: str, first: str | None, tree: Path = ROOT) -> tuple[float, float]:
    """Seconds of one evaluate from a cold (or ``first``-filled) cache; f_design."""
    with tempfile.TemporaryDirectory() as folder:
        if first is not None:
            _evaluate(first, Path(folder), tree)
        seconds, payload = _evaluate(path, Path(folder), tree)
    return seconds, float(payload["f_design"])


def _compare(label: str, row: dict, before: dict) -> None:
    """Print ``before``'s best time beside ``row``'s and put both into ``row``."""
    best, old = min(row["seconds"]), min(before["seconds"])
    row["before"] = before
    row["ratio"] = best / old
    scale = max(abs(before["f_design"]), abs(row["f_design"]), 1e-3)
    same = abs(row["f_design"] - before["f_design"]) <= 1e-9 * scale
    print(f"{'':<34} before {old:7.1f} s  ratio {best / old:5.2f}"
          f"  f_design {before['f_design']:.6g}{'' if same else '  DIFFERS'}",
          flush=True)  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--only", help="run the cases whose label contains this")
    parser.add_argument("--out", default=str(_results.RESULTS))
    parser.add_argument("--before", type=Path, help="another checkout to compare")
    args = parser.parse_args()
    rows = []
    for label, path, first, target in CASES:
        if args.only and args.only not in label:
            continue
        times, f_design, old = [], None, {"seconds": [], "f_design": None}
        for _ in range(args.repeat):
            if args.before is not None:
                seconds, old["f_design"] = _case(path, first, args.before.resolve())
                old["seconds"].append(seconds)
            seconds, f_design = _case(path, first)
            times.append(seconds)
        best = min(times)
        row = {"case": label, "seconds": times, "target": target, "f_design": f_design}
        rows.append(row)
        verdict = "met" if best <= target else "not met"
        print(f"{label:<34} {best:7.1f} s  (target {target:4.0f} s, {verdict})"
              f"  f_design {f_design:.6g}", flush=True)  # fmt: skip
        if args.before is not None:
            _compare(label, row, old)
    tree = {} if args.before is None else {"before_tree": str(args.before.resolve())}
    _results.write(__file__, {**tree, "cases": rows}, args.out)


if __name__ == "__main__":
    main()
