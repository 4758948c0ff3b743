"""``linkopt sweep``: one resumable run folder per seed, the summary table and the best
verified design (:mod:`linkopt._design.sweep`), locally and on a ``LocalCluster``."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time

import distributed  # the test extra installs linkopt[cluster]: no skip
import numpy as np
import pytest
from conftest import MECHANISMS

from linkopt._design.checkpoint import read
from linkopt._design.optimizer import OptimizerSettings
from linkopt._design.run import optimize
from linkopt._design.sweep import parse_seeds, seed_folder

FILE = str(MECHANISMS / "five_bar.toml")
# 4 particles in 2 chunks of 2, as in test_cluster.py: the same compiled programs
RUN = [
    "--particles", "4", "--iterations", "2", "--verify-rounds", "0",
    "--resolution", "8", "--workers", "2",
]  # fmt: skip


def _sweep(out, seeds: str, *extra: str) -> list[str]:
    return [sys.executable, "-m", "linkopt._cli.main", "sweep", FILE, "--seeds", seeds,
            "--out", str(out), *RUN, *extra]  # fmt: skip


def test_parse_seeds():
    assert parse_seeds("0:3") == [0, 1, 2] and parse_seeds("5,1") == [5, 1]
    for bad in ("3:3", "-1:2", "1,1", "a"):
        with pytest.raises(ValueError):
            parse_seeds(bad)


@pytest.fixture(scope="module")
def resumed_sweep(tmp_path_factory):
    """A sweep of seeds 0-1 killed (SIGKILL) once seed 0 has finished, then rerun
    with the same command: the folder, seed 0's summary.json mtime before the rerun,
    and the rerun's stderr."""
    out = tmp_path_factory.mktemp("sweep") / "sweep"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    first = subprocess.Popen(
        _sweep(out, "0:2"), stderr=subprocess.PIPE, text=True, env=env
    )
    lines = []
    for line in first.stderr:  # until seed 0's line
        lines.append(line)
        if line.startswith("seed 0:"):
            break
    first.send_signal(signal.SIGKILL)
    first.wait()
    assert any(line.startswith("seed 0:") for line in lines), "".join(lines)
    assert not (out / "summary.csv").exists()
    stamp = (seed_folder(out, 0) / "summary.json").stat().st_mtime_ns
    again = subprocess.run(_sweep(out, "0:2"), capture_output=True, text=True, env=env)
    assert again.returncode in (0, 1), again.stderr
    return out, stamp, again


def test_a_killed_sweep_resumes_and_does_not_recompute_finished_seeds(resumed_sweep):
    out, stamp, again = resumed_sweep
    assert "seed 0: already finished" in again.stderr
    assert (seed_folder(out, 0) / "summary.json").stat().st_mtime_ns == stamp
    with open(out / "summary.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["seed"] for r in rows] == ["0", "1"]
    for r in rows:  # each row is its run folder's summary
        summary = json.loads(
            (seed_folder(out, int(r["seed"])) / "summary.json").read_text()
        )
        assert int(r["iterations"]) == summary["iterations"] == 2
        assert float(r["f_design"]) == summary["f_design"]
        assert r["verified"] == str(summary["verified"])
    table = json.loads(again.stdout)
    assert [row["seed"] for row in table] == [0, 1]
    verified = [r for r in rows if r["verified"] == "True"]
    if verified:
        assert again.returncode == 0
        best = min(
            verified, key=lambda r: float(r["f_design"]) + float(r["regularizer"])
        )
        assert (out / "best.toml").read_text() == (
            seed_folder(out, int(best["seed"])) / "optimized.toml"
        ).read_text()
    else:
        assert again.returncode == 1 and not (out / "best.toml").exists()
        assert "no run of the sweep passes verification" in again.stderr


def test_a_sweep_seed_is_the_optimize_run_of_that_seed(
    resumed_sweep, five_bar, tmp_path
):
    """Seed 1 of the sweep (run by the rerun, resumed or not) is the run of
    ``linkopt optimize --seed 1`` with the same options, bit for bit (its
    optimisation: the outputs follow from it and cost a minute to remake)."""
    out, _, _ = resumed_sweep
    settings = OptimizerSettings(particles=4, iterations=2, seed=1, verify_rounds=0)
    optimize(five_bar, tmp_path / "run", settings, workers=2)
    _same_swarm(read(tmp_path / "run"), read(seed_folder(out, 1)))


def _same_swarm(a: dict, b: dict) -> None:
    for key in ("position", "velocity", "pbest_pos", "pbest_cost", "best_pos"):
        np.testing.assert_array_equal(np.array(a[key], float), np.array(b[key], float))

    def strip(run):
        return [
            {k: v for k, v in h.items() if k != "wall_time"} for h in run["history"]
        ]

    assert strip(a) == strip(b) and len(strip(a)) == 2


def test_sweep_on_a_cluster_matches_the_local_sweep(resumed_sweep, tmp_path):
    """Seed 0 as one task on a LocalCluster worker (its 2 chunks in turn) is the local
    sweep's seed 0 (2 processes), bit for bit."""
    out, _, _ = resumed_sweep
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as local:
        began = time.perf_counter()
        done = subprocess.run(
            _sweep(tmp_path / "sweep", "0:1", "--scheduler", local.scheduler_address),
            capture_output=True,
            text=True,
        )
    assert done.returncode in (0, 1), done.stderr
    assert time.perf_counter() - began < 600
    _same_swarm(read(seed_folder(tmp_path / "sweep", 0)), read(seed_folder(out, 0)))
    assert (tmp_path / "sweep" / "summary.csv").read_text().splitlines()[0] == (
        "seed,iterations,seconds,f_design,regularizer,verified"
    )
