"""A design run's settings and the limits of the design commands, without JAX: the
command line shows and checks them before it imports the engine
(:mod:`linkopt._design.optimizer` runs the swarm, :mod:`linkopt._design.maps` and
:mod:`linkopt._draw.animation` apply the limits).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from .._machine import grid_memory_cap

#: Default cap on the cells of one dense grid: 100 000 cells (a 316² verify grid, a
#: 46³ one) at ``maps.SECONDS_PER_CELL`` is about 8 minutes on one core for the
#: five-bar; ``verify``'s default grid has 1681 cells and ``plot``'s 3600.
MAX_CELLS = 100_000
#: Cap on a grid's estimated peak memory: half of this machine's memory (12 GiB of
#: 24 GiB; :func:`linkopt._machine.grid_memory_cap`), leaving the rest to the
#: interpreter, jax's compiled code and a second process. It binds before the cell cap
#: for larger states (σ_min of every cell is one batch: ~120 kB a five-bar cell).
MAX_BYTES = grid_memory_cap()
#: Frames of an animation by default, and the most it accepts (a GIF's drawing time
#: and size grow with its frames).
DEFAULT_FRAMES = 60
MAX_FRAMES = 600


@dataclass(frozen=True)
class OptimizerSettings:
    """A run's settings (their meaning: :mod:`linkopt._design.optimizer`); its
    checkpoint records them, and a resume with others is refused."""

    particles: int = 20
    iterations: int = 60
    seed: int = 0
    #: "hybrid" (PSO + partial gradient) or "gradient" (partial gradient only)
    mode: str = "hybrid"
    gradient_probability: float = 0.5
    cognitive: float = 2.0
    social: float = 2.0
    inertia_start: float = 0.9
    inertia_end: float = 0.4
    inertia_iterations: int = 100
    learning_rate: float = 1.0
    spread: float = 0.05  # initial particles: p₀ ± spread · (upper - lower), uniform
    gradient_rate: float = 0.01
    gradient_step: float = 0.02  # reference lengths
    #: f_design at or below which a design counts as feasible (the optimizer's docs)
    tolerance: float = 1e-12
    patience: int = 3
    improvement: float = 1e-3
    #: times a run whose design fails verification goes on with added targets
    verify_rounds: int = 3

    def inertia(self, iteration: int) -> float:
        fraction = min(iteration / self.inertia_iterations, 1.0)
        return self.inertia_start - (self.inertia_start - self.inertia_end) * fraction

    def to_dict(self) -> dict:
        return asdict(self)
