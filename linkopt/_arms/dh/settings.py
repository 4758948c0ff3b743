"""The settings of a DH synthesis (paper 004) and their limits, without JAX: the
command line shows and checks them before it imports the synthesis
(:mod:`linkopt._arms.dh.synthesis`, where eq. 6-10 are given).
"""

from __future__ import annotations

from dataclasses import dataclass

#: Largest settings (checked by ``synthesis``): weights of eq. 10 and counts of work.
LIMITS = {
    "weights": 1e12,
    "starts": 1000,
    "max_iterations": 1_000_000,
    "precision_rounds": 20,
    "polish_iterations": 10_000,
}


@dataclass(frozen=True)
class DHSynthesisSettings:
    """Weights of eq. 10 and optimiser settings.

    ``precision`` = ε (eq. 8), ``size_damping`` = ξ (eq. 9-10), ``b`` of eq. 6.
    ``reach_tolerance``: residual (task units) below which a target counts as reached.
    """

    precision: float = 25.0
    size_damping: float = 12.0
    b: float = 1e-10
    starts: int = 8
    seed: int = 0
    max_iterations: int = 4000
    reach_tolerance: float = 1e-3
    precision_rounds: int = 6
    polish_iterations: int = 40
