"""pyswarms' backend, imported without its logging side effects.

Every pyswarms ``Reporter`` (created at import time and by each topology/handler) calls
``logging.config.dictConfig`` with a default that writes ``report.log`` into the
current directory and sets the root logger to INFO. pyswarms reads an alternative
configuration from ``$LOG_CFG``; unless the user set one, we point it at a no-op
incremental configuration shipped with linkopt before importing pyswarms.
"""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("LOG_CFG", str(Path(__file__).with_name("pyswarms_logging.yaml")))

from pyswarms.backend.generators import create_swarm  # noqa: E402
from pyswarms.backend.handlers import BoundaryHandler  # noqa: E402
from pyswarms.backend.operators import compute_pbest, compute_position  # noqa: E402
from pyswarms.backend.topology import Star  # noqa: E402

__all__ = [
    "BoundaryHandler",
    "Star",
    "compute_pbest",
    "compute_position",
    "create_swarm",
]
