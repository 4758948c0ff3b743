"""The machine's cores and memory, read at run time, and the defaults that follow
(linkopt._machine): a 2-core, 24 GiB machine gets the figures linkopt had fixed
before (2 workers, a 12 GiB grid cap)."""

from __future__ import annotations

import os

import pytest

from linkopt import _machine
from linkopt._cli import optimize
from linkopt._design import settings

GIB = 2**30


@pytest.mark.parametrize(
    "cores, memory, workers",
    [
        (2, 24 * GIB, 2),  # the machine the defaults were sized on
        (1, 24 * GIB, 1),
        (16, 64 * GIB, 8),  # at most MAX_DEFAULT_WORKERS
        (16, 12 * GIB, 4),  # one per 3 GiB
        (4, 2 * GIB, 1),  # at least one
    ],
)
def test_default_workers_follow_cores_and_memory(cores, memory, workers):
    assert _machine.default_workers(cores, memory) == workers


def test_the_grid_cap_is_half_the_memory():
    assert _machine.grid_memory_cap(24 * GIB) == 12 * GIB
    assert _machine.grid_memory_cap(64 * GIB) == 32 * GIB


def test_cores_are_those_this_process_may_use():
    expected = (
        len(os.sched_getaffinity(0))
        if hasattr(os, "sched_getaffinity")
        else os.cpu_count()
    )
    assert _machine.cores() == expected


def test_memory_is_thephysical_memory_or_a_lowercgroup_limit():
    physical = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    found = _machine.memory()
    assert 0 < found <= physical
    limit = _machine.cgroup_limit()
    assert found == min(physical, limit or physical)


def test_the_cli_and_the_grids_use_this_machines_figures():
    assert optimize.WORKERS == _machine.default_workers()
    assert settings.MAX_BYTES == _machine.grid_memory_cap()


def test_a_cpu_affinity_limits_the_default_workers():
    """In a fresh process pinned to one core, the default --workers is 1."""
    import subprocess
    import sys

    if not hasattr(os, "sched_setaffinity"):
        pytest.skip("no CPU affinity on this system")
    code = (
        "import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); "
        "from linkopt._cli import optimize; print(optimize.WORKERS)"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert done.stdout.strip() == "1"
