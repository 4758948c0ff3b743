"""The particle swarm's state and its three rules, in numpy: personal bests, the global
best of the star topology, and positions kept in bounds by the ``nearest`` rule.

These are pyswarms' backend rules (``compute_pbest``, ``Star.compute_gbest``,
``compute_position`` with ``BoundaryHandler("nearest")``), written here with the same
names and the same operations, so results are bitwise those of pyswarms. linkopt does
not import pyswarms: every pyswarms object configures Python's root logger and writes
``report.log`` into the working directory unless ``$LOG_CFG`` says otherwise, and
linkopt neither sets environment variables nor touches the user's logging.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Swarm:
    """A swarm's arrays: positions and velocities ``(N, D)``, personal bests ``(N, D)``
    and ``(N,)``, the global best ``(D,)`` and its cost, this iteration's costs."""

    position: np.ndarray
    velocity: np.ndarray
    options: dict = field(default_factory=dict)
    pbest_pos: np.ndarray | None = None
    pbest_cost: np.ndarray | None = None
    best_pos: np.ndarray | None = None
    best_cost: float = np.inf
    current_cost: np.ndarray | None = None

    @property
    def n_particles(self) -> int:
        return self.position.shape[0]

    @property
    def dimensions(self) -> int:
        return self.position.shape[1]


def create_swarm(n_particles: int, dimensions: int, options: dict) -> Swarm:
    """A swarm of zeros; the caller sets its arrays."""
    zeros = np.zeros((n_particles, dimensions))
    return Swarm(zeros, zeros.copy(), dict(options))


def compute_pbest(swarm: Swarm) -> tuple[np.ndarray, np.ndarray]:
    """Personal bests: a particle's position replaces its best where its cost is
    lower."""
    mask_cost = swarm.current_cost < swarm.pbest_cost
    mask_pos = np.repeat(mask_cost[:, np.newaxis], swarm.dimensions, axis=1)
    new_pbest_pos = np.where(~mask_pos, swarm.pbest_pos, swarm.position)
    new_pbest_cost = np.where(~mask_cost, swarm.pbest_cost, swarm.current_cost)
    return new_pbest_pos, new_pbest_cost


class Star:
    """The star topology: every particle sees the whole swarm."""

    @staticmethod
    def compute_gbest(swarm: Swarm) -> tuple[np.ndarray, float]:
        """The lowest personal best where it beats the global best, else the global
        best (the first particle on a tie)."""
        if np.min(swarm.pbest_cost) < swarm.best_cost:
            return swarm.pbest_pos[np.argmin(swarm.pbest_cost)], np.min(
                swarm.pbest_cost
            )
        return swarm.best_pos, swarm.best_cost


class BoundaryHandler:
    """Positions out of bounds set to the nearest bound (the one strategy linkopt
    uses)."""

    def __init__(self, strategy: str = "nearest"):
        if strategy != "nearest":
            raise ValueError(f"boundary strategy: expected 'nearest', got {strategy!r}")
        self.strategy = strategy

    def __call__(self, position: np.ndarray, bounds) -> np.ndarray:
        lb, ub = bounds
        new_pos = np.where(position < lb, lb, position)
        return np.where(position > ub, ub, new_pos)


def compute_position(swarm: Swarm, bounds, handler: BoundaryHandler) -> np.ndarray:
    """Each particle moved by its velocity, then kept in ``bounds``."""
    return handler(swarm.position + swarm.velocity, bounds)
