"""The machine linkopt runs on, read at run time: the cores this process may use and
its memory, and the defaults that follow from them (worker processes, a grid's memory
cap). JAX-free.

A larger machine gets more workers and a larger grid cap, a smaller one less.
``docs/performance.md`` says how an iteration's work splits over
workers and where adding more stops paying.
"""

from __future__ import annotations

import os
from pathlib import Path

#: Memory one worker process is allowed for in the default worker count: a Python and
#: JAX runtime with a mechanism's compiled programs (a few hundred MB to about 1 GiB),
#: and its batch's arrays, with room to spare: 24 GiB gives 8.
WORKER_MEMORY = 3 * 2**30
#: The most workers by default, however many cores: the default swarm of 20 particles
#: splits into chunks of 2-3 there, below which a chunk's fixed costs (a call's
#: dispatch, the calling process's serial share) outweigh what another core adds
#: (``docs/performance.md``). ``--workers`` takes up to 64.
MAX_DEFAULT_WORKERS = 8
#: The share of the memory one dense grid may take (a 2-D or 3-D map, ``verify``): the
#: rest stays for the interpreter, JAX's compiled code and a second process.
GRID_MEMORY_SHARE = 0.5
#: What a machine whose memory cannot be read is taken to have.
FALLBACK_MEMORY = 24 * 2**30
#: cgroup files that may cap this process's memory below the machine's (v2, then v1).
CGROUP_LIMITS = (
    Path("/sys/fs/cgroup/memory.max"),
    Path("/sys/fs/cgroup/memory/memory.limit_in_bytes"),
)


def cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one,
    e.g. under ``taskset`` or a container's cpuset), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


def physical_memory() -> int | None:
    """The machine's physical memory in bytes (None where the system does not say)."""
    try:
        pages, size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):  # Windows, or not reported
        return None
    return pages * size if pages > 0 and size > 0 else None


def cgroup_limit() -> int | None:
    """The memory limit of this process's cgroup in bytes (None where there is none,
    or it is ``max``)."""
    for path in CGROUP_LIMITS:
        try:
            text = path.read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            return int(text)
    return None


def memory() -> int:
    """Bytes of memory this process may use: the machine's physical memory, or its
    cgroup's limit where lower (:data:`FALLBACK_MEMORY` where neither can be read)."""
    known = [m for m in (physical_memory(), cgroup_limit()) if m]
    return min(known) if known else FALLBACK_MEMORY


def default_workers(cores: int | None = None, memory_bytes: int | None = None) -> int:
    """The default ``--workers``: one per core, at most one per :data:`WORKER_MEMORY`
    of memory and at most :data:`MAX_DEFAULT_WORKERS`, at least 1 (2 on a 2-core
    machine with 24 GiB). Arguments default to this machine's."""
    cores = globals()["cores"]() if cores is None else cores
    memory_bytes = memory() if memory_bytes is None else memory_bytes
    return max(1, min(cores, MAX_DEFAULT_WORKERS, memory_bytes // WORKER_MEMORY))


def grid_memory_cap(memory_bytes: int | None = None) -> int:
    """The cap on one grid's estimated peak memory: :data:`GRID_MEMORY_SHARE` of the
    memory (12 GiB of 24 GiB). ``memory_bytes`` defaults to this machine's."""
    memory_bytes = memory() if memory_bytes is None else memory_bytes
    return int(memory_bytes * GRID_MEMORY_SHARE)
