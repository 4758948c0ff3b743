"""Where a benchmark keeps its figures: ``benchmarks/results/<script>.json``.

Every ``bench_*.py`` calls :func:`write` once at the end with its figures; the file
holds them beside the date, the commit and the machine, and the documentation's
performance page (``docs/hooks.py``) is built from these files. The shape:

    {
      "date": "YYYY-MM-DD HH:MM",
      "commit": "<short hash>", with "-dirty" when tracked files differ from it,
      "machine": {"cores": int, "load": float, "python": "3.x.y"},
      <the script's figures>
    }

``load`` is the 1-minute load average when the benchmark started (this module is
imported first): on a loaded machine the figures are not comparable. The figures are
named by the script; the performance page shows a list of flat records as a table (a
list of numbers in a cell as repeated runs: its median and count), a record as a
two-column table and anything else on one line.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
#: The 1-minute load average at import, i.e. when the benchmark started.
LOAD_AT_START = os.getloadavg()[0]


def _git(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["git", *args], cwd=ROOT, capture_output=True, text=True, check=False
    )


def commit() -> str:
    """The short hash of ``HEAD``, ``-dirty`` when tracked files differ from it;
    ``unknown`` outside a git checkout."""
    head = _git("rev-parse", "--short", "HEAD").stdout.strip()
    if not head:
        return "unknown"
    # plumbing, so the index is only read
    dirty = _git("diff-index", "--quiet", "HEAD", "--").returncode == 1
    return head + ("-dirty" if dirty else "")


def machine() -> dict:
    """Cores, the load average when the benchmark started, Python's version."""
    return {
        "cores": os.cpu_count(),
        "load": round(LOAD_AT_START, 2),
        "python": platform.python_version(),
    }


def write(script: str, figures: dict, folder: str | Path = RESULTS) -> Path:
    """Write ``figures`` (JSON-able) with the date, commit and machine to
    ``folder/<script's name without .py>.json``; returns the path. ``script`` is the
    calling script's ``__file__``."""
    record = {
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "commit": commit(),
        "machine": machine(),
        **figures,
    }
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{Path(script).stem}.json"
    path.write_text(json.dumps(record, indent=2, default=_plain) + "\n")
    return path


def _plain(value):
    """numpy scalars and arrays as Python numbers and lists."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"not JSON-able: {type(value).__name__}")
