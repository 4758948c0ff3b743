"""Verification in the loop: a run verifies its design before it stops.

The sparse samples of ``f_design`` carry no guarantee (paper Sec. VII), and a sample
minimisation that stopped at its cap may read low (:mod:`linkopt._design.evaluation`),
so a run can accept a design that ``linkopt verify`` rejects. When a run has finished
with a feasible design, :func:`verification_round` verifies it on the dense grid
(:func:`linkopt._design.verify.verify`, default resolution). Where verification fails,
the failing places become IK targets of the evaluation (each target's IK sample goes
there and its adversarial sample starts there):

- one unreached cell (the first in grid order), so the reach term counts it;
- the cell of the largest ``f_sing`` when that is at or above ``α₋``, so the IK sample
  sits where the culled singularity term is already positive;
- with ``[collision]`` enabled, the cell of the least clearance when that is below the
  clearance, so the IK sample sits in the collision and the collision term of
  ``f_design`` counts it;
- with motor limits, the cell that needs a motor furthest beyond its limits, so that
  target's IK sample, held within the limits, leaves a reach residual.

and the run goes on (:func:`linkopt._design.optimizer.reopen`). The budget is
``verify_rounds`` such continuations of at most ``iterations`` iterations each; a run
still failing after them, or whose failing places are all targets already, stops with
its last design and says that it is unverified. Every round is recorded (iteration,
the design, coverage, worst ``f_sing``, the targets it added); ``summary.json`` lists
them.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._engine.model import Mechanism
from .evaluation import targets
from .optimizer import OptimizerSettings, SwarmRun, best_design, reopen
from .verify import Verification, verify


def with_targets(mech: Mechanism, targets) -> Mechanism:
    """``mech`` with the IK targets ``targets`` (file units, ``(E, K)``) added to its
    ``[evaluation].targets``."""
    added = tuple(tuple(float(v) for v in t) for t in targets)
    if not added:
        return mech
    evaluation = dataclasses.replace(
        mech.evaluation, targets=mech.evaluation.targets + added
    )
    return dataclasses.replace(mech, evaluation=evaluation)


def wants_round(run: SwarmRun, settings: OptimizerSettings) -> bool:
    """Whether ``run`` has finished with a feasible design that no round has verified
    yet (and verification in the loop is on)."""
    checked = bool(run.rounds) and run.rounds[-1]["iteration"] == run.iteration
    return (
        settings.verify_rounds > 0
        and run.finished
        and run.result_feasible
        and not checked
    )


def failing_places(mech: Mechanism, check: Verification) -> list[list[float]]:
    """The places (output values, file units) where ``check`` failed and that are not
    IK targets yet (module docstring)."""
    places = []
    if check.unreached_example is not None:
        places.append(np.asarray(check.unreached_example, dtype=float))
    if check.coverage > 0 and check.max_f_sing >= check.threshold:
        places.append(np.asarray(check.worst_outputs, dtype=float))
    if collided(mech, check):
        places.append(np.asarray(check.collision_outputs, dtype=float))
    if check.beyond_limits:
        places.append(np.asarray(check.limit_outputs, dtype=float))
    known = targets(mech)
    scale = np.asarray(mech.output_scale, dtype=float)
    new = []
    for place in places:
        seen = np.vstack([known, *new]) if new else known
        if not np.any(np.all(np.abs(seen - place) <= 1e-9 * scale, axis=1)):
            new.append(place)
    return [p.tolist() for p in new]


def collided(mech: Mechanism, check: Verification) -> bool:
    """Whether ``check`` found two checked links closer than the clearance (never
    without ``[collision]`` enabled)."""
    return (
        check.min_clearance is not None
        and check.collision_outputs is not None
        and check.min_clearance < mech.collision.clearance
    )


def _record(run: SwarmRun, check: Verification, added: list) -> dict:
    """The round's record (module docstring); ``verification`` is what
    ``verification.json`` holds for the design."""
    return {
        "round": len(run.rounds),
        "iteration": run.iteration,
        "design": [float(v) for v in best_design(run)],
        "passed": bool(check.passed),
        "coverage": float(check.coverage),
        "max_f_sing": float(check.max_f_sing),
        "threshold": float(check.threshold),
        "added_targets": added,
        "verification": check.as_json(),
    }


def verification_round(
    mech: Mechanism, run: SwarmRun, settings: OptimizerSettings
) -> SwarmRun:
    """Verify the finished ``run``'s design on ``mech`` (the file's mechanism with the
    targets added so far) and record the round; where it fails and the budget allows,
    add the failing places as targets and :func:`reopen` the run."""
    check = verify(mech, best_design(run))
    added = [] if check.passed else failing_places(mech, check)
    reopening = bool(added) and len(run.rounds) < settings.verify_rounds
    record = _record(run, check, added if reopening else [])
    run = dataclasses.replace(run, rounds=(*run.rounds, record))
    return reopen(run, settings) if reopening else run
