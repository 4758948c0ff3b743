"""Link clearance in an optimisation's record: the collision columns of
``history.csv`` and the ``collision`` entry of ``summary.json``.

Both exist only for a file with ``[collision]`` enabled (decided in Python from the
file, :func:`linkopt._engine.collision.has_collision`), so a run of any other file
writes exactly the columns and keys it wrote before. ``collision`` is the collision
part of ``f_design`` (``weight`` times the term, :mod:`linkopt._design.evaluation`:
``f_design - reach - singularity``), ``min_clearance`` the least clearance (file
units) over the design's IK and collision sample states, the poses ``f_design``
sees; the verification's dense grid may find a smaller one between them
(``verification.json``).
"""

from __future__ import annotations

import jax
import numpy as np

from .._engine.collision import Clearance, clearance, has_collision, pair_names
from .._engine.model import Mechanism
from .evaluation import Evaluation

#: The history columns of a file with ``[collision]`` enabled, after the others.
COLLISION_COLUMNS = ("collision", "min_clearance")


def sample_clearance(mech: Mechanism, ev: Evaluation, design=None) -> Clearance:
    """:class:`~linkopt.Clearance` of one design's IK then collision sample states
    (``2T`` rows, the states of its collision term, :mod:`linkopt._design.evaluation`;
    ``design`` in file units, None: the file's)."""
    states = np.concatenate([np.asarray(ev.ik_states), np.asarray(ev.col_states)])
    return clearance(mech, states, design=design)


def collision_share(ev: Evaluation) -> float:
    """The collision part of one design's ``f_design`` (module docstring)."""
    return float(ev.f_design) - float(ev.reach) - float(ev.singularity)


def _one(ev: Evaluation, k: int) -> Evaluation:
    """Design ``k`` of a batch's evaluation."""
    return jax.tree_util.tree_map(lambda field: np.asarray(field)[k], ev)


def history_columns(mech: Mechanism, ev: Evaluation, designs, k: int) -> dict:
    """The collision columns (:data:`COLLISION_COLUMNS`) of design ``k`` of a batch
    evaluation ``ev`` of ``designs`` (file units); empty without ``[collision]``
    enabled."""
    if not has_collision(mech):
        return {}
    one = _one(ev, k)
    least = sample_clearance(mech, one, np.asarray(designs)[k]).minimum
    return {
        "collision": collision_share(one),
        "min_clearance": float(np.min(least)) if len(least) else float("inf"),
    }


def history_fields(mech: Mechanism, fields) -> list[str]:
    """``fields``, then the collision columns when the file checks collisions."""
    return [*fields, *(COLLISION_COLUMNS if has_collision(mech) else ())]


def summary_entry(mech: Mechanism, final: Evaluation, design, checks: dict) -> dict:
    """``summary.json``'s ``collision`` entry for the run's design (``final``: its
    evaluation; ``checks``: ``verification.json``'s contents); empty without
    ``[collision]`` enabled."""
    if not has_collision(mech):
        return {}
    result = sample_clearance(mech, final, design)
    k = int(np.argmin(result.minimum)) if len(result.minimum) else -1
    pair = None if k < 0 or result.worst[k] < 0 else pair_names(mech, result.worst[k])
    return {
        "collision": {
            "weight": mech.collision.weight,
            "clearance": mech.collision.clearance,
            "share": collision_share(final),
            "min_clearance": float(result.minimum[k]) if k >= 0 else float("inf"),
            "pair": None if pair is None else list(pair),
            "verified_min_clearance": checks["optimized"].get("min_clearance"),
            "initial_verified_min_clearance": checks["initial"].get("min_clearance"),
        }
    }
