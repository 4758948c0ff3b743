"""Per-iteration overhead of the Dask path (``--scheduler``) against the local pool.

Run: ``.venv/bin/python benchmarks/bench_cluster.py [--particles 20] [--repeats 10]``

Five-bar, the default 20 particles, 2 chunks. Times ``evaluate`` of one swarm (the
per-iteration work that goes to the workers) with

- ``local``: :class:`linkopt._design.workers.Workers` with 2 processes (this one and a
  spawned one; the local default on 2 cores),
- ``in-process``: the same 2 chunks one after another in this process
  (:class:`linkopt._design.sweep.InProcessChunks`: no parallelism, the baseline of the
  evaluation's own cost),
- ``cluster``: :class:`linkopt._design.cluster.ClusterWorkers` on a
  ``distributed.LocalCluster`` of 2 single-threaded worker processes (both chunks
  there; this process waits),

and, to separate the fixed cost from the evaluation (whose time swings with the
machine's load), the round trip of 2 no-op tasks (``numpy.copy`` of a chunk's designs)
on the local pool's spawned process and on the cluster; all after one warm-up call
each (compilation or the persistent cache's load, and the workers' start-up,
excluded); and checks that the three evaluations give the same numbers. The cluster's
overhead per iteration is its median minus the local pool's: the two tasks'
scheduling, pickling of designs and results and the round trips, against the local
pool's one pickled chunk. Baseline: the local pool (the default ``linkopt optimize``).
Figures are the median and the spread (min-max) over ``--repeats`` calls; on a loaded
machine the spread is large, so compare medians. Writes them to
``benchmarks/results/bench_cluster.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from pathlib import Path

import _results
import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _time(pool, designs, repeats: int) -> tuple[list[float], object]:
    first = pool.evaluate(designs)  # warm-up
    times = []
    for _ in range(repeats):
        began = time.perf_counter()
        pool.evaluate(designs)
        times.append(time.perf_counter() - began)
    return times, first


def _line(name: str, times: list[float]) -> str:
    return (
        f"{name:11s} median {statistics.median(times) * 1e3:8.1f} ms  "
        f"(min {min(times) * 1e3:.1f}, max {max(times) * 1e3:.1f}, n={len(times)})"
    )


def _round_trips(submit, chunks, repeats: int) -> list[float]:
    """Seconds for the no-op tasks of all chunks to come back, ``repeats`` times."""
    [f.result() for f in [submit(np.copy, c) for c in chunks]]  # warm-up
    times = []
    for _ in range(repeats):
        began = time.perf_counter()
        [f.result() for f in [submit(np.copy, c) for c in chunks]]
        times.append(time.perf_counter() - began)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()

    import distributed

    import linkopt
    from linkopt._design.cluster import ClusterWorkers
    from linkopt._design.optimizer import OptimizerSettings, start
    from linkopt._design.sweep import InProcessChunks
    from linkopt._design.workers import Workers

    mech = linkopt.load(ROOT / "mechanisms/five_bar.toml")
    designs = start(mech, OptimizerSettings(particles=args.particles)).position
    results = {}
    with InProcessChunks(mech, 2) as pool:
        results["in-process"] = _time(pool, designs, args.repeats)
    chunks = [designs[: len(designs) // 2], designs[len(designs) // 2 :]]
    trips = {}
    with Workers(mech, 2) as pool:
        results["local"] = _time(pool, designs, args.repeats)
        trips["local"] = _round_trips(pool._pool.submit, chunks, 5 * args.repeats)
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
        ClusterWorkers(mech, 2, client) as pool,
    ):
        results["cluster"] = _time(pool, designs, args.repeats)
        trips["cluster"] = _round_trips(
            lambda f, c: client.submit(f, c, pure=False), chunks, 5 * args.repeats
        )
    print(f"five-bar, {args.particles} particles in 2 chunks, one evaluate per call")
    for name, (times, _) in results.items():
        print(_line(name, times))
    print("round trip of 2 no-op tasks (the fixed cost per iteration):")
    for name, times in trips.items():
        print(_line(name, times))
    reference = results["local"][1]
    identical = {}
    for name, (_, ev) in results.items():
        same = all(
            a is b is None or np.array_equal(a, b, equal_nan=True)
            for a, b in (
                (getattr(ev, f.name), getattr(reference, f.name))
                for f in dataclasses.fields(ev)
            )
        )
        identical[name] = same
        print(f"{name:11s} bit-identical to local: {same}")
    local = statistics.median(results["local"][0])
    dask = statistics.median(results["cluster"][0])
    print(
        f"cluster overhead per iteration vs the local pool (baseline): "
        f"{(dask - local) * 1e3:+.1f} ms ({dask / local:.2f}x); fixed cost "
        f"{statistics.median(trips['cluster']) * 1e3:.1f} ms against "
        f"{statistics.median(trips['local']) * 1e3:.1f} ms"
    )
    pools = [
        {
            "pool": name,
            "evaluate_s": times,
            "round_trip_s": trips.get(name),
            "bit_identical_to_local": identical[name],
        }
        for name, (times, _) in results.items()
    ]
    _results.write(
        __file__,
        {
            "mechanism": "five_bar",
            "particles": args.particles,
            "chunks": 2,
            "pools": pools,
            "cluster_overhead_s": dask - local,
        },
    )


if __name__ == "__main__":
    main()
