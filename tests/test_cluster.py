"""``--scheduler``: each iteration's particle chunks on a Dask cluster
(:mod:`linkopt._design.cluster`), bit-identical to the local run.

"The same run" here: the same mechanism file, settings (seed included) and ``workers``
(the number of chunks), on workers with the same linkopt and JAX; the local reference
is :func:`linkopt._design.run.optimize` with a real two-process pool. The cluster is a
``LocalCluster`` of two single-threaded worker processes, as in the issue.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import cloudpickle  # distributed's dependency
import distributed  # the test extra installs linkopt[cluster]: no skip
import numpy as np
import pytest
from conftest import MECHANISMS

from linkopt._cli.main import main
from linkopt._design import cluster
from linkopt._design.checkpoint import read
from linkopt._design.optimizer import OptimizerSettings
from linkopt._design.run import optimize
from linkopt._engine.model import fingerprint

# 4 particles in 2 chunks of 2: one batch shape, shared with test_sweep.py
SETTINGS = OptimizerSettings(particles=4, iterations=2, seed=0, verify_rounds=0)
WORKERS = 2

cloudpickle.register_pickle_by_value(sys.modules[__name__])  # KillFirstChunk


@pytest.fixture(scope="module")
def client():
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as local,
        distributed.Client(local) as c,
    ):
        yield c


@pytest.fixture(scope="module")
def local_run(five_bar, tmp_path_factory):
    out = tmp_path_factory.mktemp("local") / "run"
    optimize(five_bar, out, SETTINGS, workers=WORKERS)
    return read(out)


def _same_run(a: dict, b: dict) -> None:
    """Two checkpoints hold the same swarm, bit for bit (NaN where NaN), and the same
    history apart from the wall times."""
    assert a.keys() == b.keys()
    for key in a:
        if key == "history":
            strip = [{k: v for k, v in h.items() if k != "wall_time"} for h in a[key]]
            assert strip == [
                {k: v for k, v in h.items() if k != "wall_time"} for h in b[key]
            ]
        elif isinstance(a[key], list) and a[key] and isinstance(a[key][0], list):
            np.testing.assert_array_equal(np.array(a[key]), np.array(b[key]))
        else:
            assert a[key] == b[key] or (a[key] != a[key] and b[key] != b[key]), key


def test_cluster_run_is_bit_identical_to_the_local_run(
    five_bar, client, local_run, tmp_path
):
    held = []  # after each iteration: the mechanisms each worker holds
    run = cluster.optimize_on_cluster(
        client,
        five_bar,
        tmp_path / "run",
        SETTINGS,
        workers=WORKERS,
        progress=lambda record: held.append(
            client.run(lambda: sorted(cluster.MECHANISMS))
        ),
    )
    assert run.iteration == SETTINGS.iterations
    _same_run(read(tmp_path / "run"), local_run)
    # both workers held the mechanism (the plugin's), under its fingerprint
    assert [len(h) for h in held] == [2] * SETTINGS.iterations
    assert all(v == [fingerprint(five_bar)] for h in held for v in h.values())
    # unregistered at close: the workers drop it
    assert all(v == [] for v in client.run(lambda: sorted(cluster.MECHANISMS)).values())


class KillFirstChunk(distributed.WorkerPlugin):
    """SIGKILLs the worker that starts the first chunk task after the marker file is
    armed (once: the marker records it)."""

    def __init__(self, marker: str):
        self.marker = marker

    def transition(self, key, start, finish, **kwargs):
        name = key if isinstance(key, str) else str(key)
        if finish == "executing" and "_evaluate_on_worker" in name:
            path = Path(self.marker)
            if path.read_text() == "armed":
                path.write_text(f"killed {os.getpid()}")
                os.kill(os.getpid(), signal.SIGKILL)


def test_a_worker_killed_mid_iteration_is_replaced_and_the_run_is_unchanged(
    five_bar, client, local_run, tmp_path
):
    marker = tmp_path / "marker"
    marker.write_text("armed")
    client.register_plugin(KillFirstChunk(str(marker)), name="kill-first-chunk")
    before = set(client.scheduler_info()["workers"])
    try:
        cluster.optimize_on_cluster(
            client, five_bar, tmp_path / "run", SETTINGS, workers=WORKERS
        )
    finally:
        client.unregister_worker_plugin("kill-first-chunk")
    assert marker.read_text().startswith("killed")
    # the nanny replaced the killed worker: another worker name took its place
    client.wait_for_workers(2, timeout=120)
    assert set(client.scheduler_info()["workers"]) != before
    _same_run(read(tmp_path / "run"), local_run)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_scheduler_is_one_line_naming_address_and_timeout(tmp_path, capsys):
    address = f"tcp://127.0.0.1:{_free_port()}"
    rc = main(
        [
            "optimize",
            str(MECHANISMS / "five_bar.toml"),
            "--out",
            str(tmp_path / "run"),
            "--scheduler",
            address,
            "--connect-timeout",
            "1",
        ]
    )
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1, err
    assert address in err and "within 1 s" in err and "Traceback" not in err


def test_missing_distributed_says_how_to_install(monkeypatch, tmp_path, capsys):
    import linkopt._design

    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails, as if absent
    monkeypatch.delitem(sys.modules, "linkopt._design.cluster")
    monkeypatch.delattr(linkopt._design, "cluster")
    rc = main(
        [
            "optimize",
            str(MECHANISMS / "five_bar.toml"),
            "--out",
            str(tmp_path / "run"),
            "--scheduler",
            "tcp://127.0.0.1:1",
        ]
    )
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1
    assert "pip install 'linkopt[cluster]'" in err


def test_import_linkopt_loads_no_dask():
    code = (
        "import sys, linkopt, linkopt._cli.main, linkopt._design.sweep; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('distributed', 'dask')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"
