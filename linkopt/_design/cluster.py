"""Each iteration's particle chunks on a Dask cluster's workers (``--scheduler``).

:class:`ClusterWorkers` has the interface of :class:`~linkopt._design.workers.Workers`
and its chunks: the particles are split into ``count`` contiguous chunks exactly as a
local run with ``count`` workers splits them (``Workers._chunks``), every chunk goes to
the cluster as one task, and the partial gradients are computed chunk by chunk in the
calling process, as locally. A chunk's numbers depend only on its designs and the
mechanism, not on the process that computes them, so a run with ``--scheduler`` is
bit-identical to a local run of the same mechanism file, settings (seed included) and
``--workers`` (the number of chunks, not the number of Dask workers), provided that the
Dask workers run the same linkopt, JAX and jaxlib on the same kind of CPU (XLA compiles
for the CPU it runs on; another instruction set may order floating-point sums
differently). ``tests/test_cluster.py`` checks it.

Each worker holds the mechanism once: a :class:`MechanismPlugin` (a Dask worker plugin,
also given to workers that join later, a replacement for a lost one included) stores it
in a per-process table keyed by the mechanism's fingerprint
(:func:`linkopt._engine.model.fingerprint`, which also keys the traced programs), and
the tasks name only that key and their designs. The evaluation program is compiled (or
loaded from the persistent compilation cache) at a worker's first chunk and kept by its
process. The mechanism travels pickled, so the workers need linkopt installed but not
the mechanism file.

A worker lost mid-task (killed, out of memory, a crash in XLA) is Dask's to handle: the
scheduler gives its task to another worker, up to ``distributed.scheduler.allowed-
failures`` times (3 by default), after which the task fails with ``KilledWorker`` and
this process computes that chunk itself, as :class:`Workers` does when its pools run
out. Either way the run goes on bit-identical.

This module imports :mod:`distributed`; only ``--scheduler`` and ``linkopt sweep``
import this module, so ``import linkopt`` and a local run never load Dask.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np
from distributed import Client, KilledWorker, WorkerPlugin
from jaxtyping import Array, Float

from .._cache import requested
from .._config import adopt, one_blas_thread
from .._engine.model import Mechanism, fingerprint
from .._errors import InputError
from .evaluation import Evaluation, evaluate
from .optimizer import OptimizerSettings, SwarmRun
from .sweep import optimize_with_pool
from .workers import Workers, concatenate

MECHANISMS: dict[str, Mechanism] = {}  # in each Dask worker, by fingerprint


class MechanismPlugin(WorkerPlugin):
    """Gives each worker (present or joining later) the mechanism, once."""

    def __init__(self, mech: Mechanism):
        self.mech = mech
        self.key = fingerprint(mech)
        self.caches = requested()  # the caches the client uses, the worker uses too

    def setup(self, worker) -> None:
        adopt(self.caches)
        MECHANISMS[self.key] = self.mech
        one_blas_thread()  # for the worker's lifetime, as in Workers' processes

    def teardown(self, worker) -> None:
        MECHANISMS.pop(self.key, None)


def _evaluate_on_worker(key: str, designs: np.ndarray) -> Evaluation:
    """One chunk, on a Dask worker holding the mechanism ``key``."""
    mech = MECHANISMS.get(key)
    if mech is None:  # the plugin runs before any task; this would be a Dask bug
        raise RuntimeError(f"this Dask worker holds no mechanism {key[:12]}")
    return jax.tree_util.tree_map(np.asarray, evaluate(mech, designs))


def connect(address: str, timeout: float) -> Client:
    """A client of the scheduler at ``address``; :class:`~linkopt.InputError` naming
    the address and the timeout when none answers."""
    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as err:
        reason = " ".join(str(err).split()) or type(err).__name__
        raise InputError(
            f"--scheduler {address}: no Dask scheduler answered within {timeout:g} s "
            f"({reason[:200]})"
        ) from None


class ClusterWorkers(Workers):
    """:class:`~linkopt._design.workers.Workers` whose ``count`` chunks are evaluated
    on the workers of ``client``'s cluster (module docstring)."""

    def __init__(self, mech: Mechanism, count: int, client: Client):
        self.client = client
        super().__init__(mech, count)
        self.computed_here = 0  # chunks computed here after KilledWorker
        self._plugin = f"linkopt-mechanism-{self.key[:16]}"
        client.register_plugin(MechanismPlugin(mech), name=self._plugin)

    def _start_pool(self) -> None:
        return None  # the cluster is the pool

    def evaluate(self, designs: Float[Array, "N n_p"]) -> Evaluation:
        """:func:`linkopt._design.evaluation.evaluate` of a batch, chunk by chunk on
        the cluster, as numpy arrays."""
        designs = np.asarray(designs, dtype=float)
        chunks = [designs[c] for c in self._chunks(len(designs))]
        futures = [
            self.client.submit(_evaluate_on_worker, self.key, chunk, pure=False)
            for chunk in chunks
        ]
        parts = []
        for future, chunk in zip(futures, chunks):
            try:
                parts.append(future.result())
            except KilledWorker:  # Dask's retries ran out (module docstring)
                self.computed_here += 1
                with one_blas_thread():
                    parts.append(
                        jax.tree_util.tree_map(np.asarray, evaluate(self.mech, chunk))
                    )
        return concatenate(parts)

    def close(self) -> None:
        try:
            self.client.unregister_worker_plugin(self._plugin)
        except Exception:  # noqa: BLE001  (the cluster may be gone; nothing to undo)
            pass


def optimize_on_cluster(
    client: Client,
    mech: Mechanism,
    out: str | Path,
    settings: OptimizerSettings,
    *,
    resume: bool = False,
    progress: Callable[[dict], None] | None = None,
    workers: int = 1,
) -> SwarmRun:
    """:func:`linkopt._design.run.optimize` with each iteration's ``workers`` chunks
    on ``client``'s cluster: the same checkpoints, resume, verification rounds and
    progress records (:func:`linkopt._design.sweep.optimize_with_pool`)."""
    return optimize_with_pool(
        lambda current: ClusterWorkers(current, workers, client),
        mech,
        out,
        settings,
        resume=resume,
        progress=progress,
    )
