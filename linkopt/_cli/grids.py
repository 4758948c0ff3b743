"""The options and progress lines of the commands that compute grids (``plot``,
``verify``): the cap on a grid's cells and the periodic progress line on stderr.
"""

from __future__ import annotations

import sys
import time

from .._design.settings import MAX_BYTES, MAX_CELLS

#: Seconds between two progress lines of the same map (the first wave of each map
#: is always reported).
PROGRESS_INTERVAL = 3.0


def map_progress(interval: float = PROGRESS_INTERVAL):
    """A ``progress`` callback for the maps (:mod:`linkopt._design.maps`): one stderr
    line when a map starts and then at most every ``interval`` seconds, with the
    elapsed time."""
    began = time.perf_counter()
    last = {"stage": None, "at": -float("inf")}

    def report(record: dict) -> None:
        now = time.perf_counter()
        if "cells" not in record:  # a stage of its own
            print(f"  {record['stage']} ...", file=sys.stderr, flush=True)
            return
        done = record["cells"] >= record["of"]
        if record["stage"] == last["stage"] and now - last["at"] < interval:
            return
        last.update(stage=record["stage"], at=now)
        print(
            f"  {record['stage']}: {record['cells']}/{record['of']} cells visited"
            f"{' (done)' if done else ''}, {now - began:.0f} s",
            file=sys.stderr,
            flush=True,
        )

    return report


def add_max_cells(cmd) -> None:
    cmd.add_argument(
        "--max-cells",
        type=int,
        default=MAX_CELLS,
        help=(
            f"refuse a grid of more cells (default {MAX_CELLS}); the estimated "
            f"memory is capped too ({MAX_BYTES / 2**30:.3g} GiB here, half of the "
            "machine's memory)"
        ),
    )
