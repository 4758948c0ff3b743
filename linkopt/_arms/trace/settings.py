"""The search settings of a trace synthesis (paper 002), without JAX: the command line
shows them before it imports the synthesis (:mod:`linkopt._arms.trace.synthesis`).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TraceSettings:
    """Search settings.

    ``restarts``: seeded initial guesses per (links, bound) stage; ``best_of``: verified
    designs to collect in the successful stage before returning the shortest; ``links``
    and ``swept``: the stages, in order. Fractions of the task size: ``reach_margin``
    (distance kept from the annulus boundary), ``clearance_margin`` (added to every
    obstacle radius in the NLP, so that tight optima survive the verifier's motion
    bound), ``smoothing`` (temperature of the conservative soft maxima in the
    swept-area distances) and ``feasibility_tol``."""

    restarts: int = 6
    max_iterations: int = 300
    reach_margin: float = 2e-3
    clearance_margin: float = 2e-3
    smoothing: float = 1e-3
    feasibility_tol: float = 1e-7
    links: tuple[int, ...] = (2, 3)
    best_of: int = 1
    swept: tuple[str, ...] = ("over", "app")
