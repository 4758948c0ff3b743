"""Verification in the loop: a run verifies its design before it stops.

The sparse samples of ``f_design`` carry no guarantee (paper Sec. VII), and a sample
minimisation that stopped at its cap may read low (:mod:`linkopt._design.evaluation`),
so a run can accept a design that ``linkopt verify`` rejects. When a run has finished
with a feasible design, or with a design whose samples show no singularity (the
singularity part of its ``f_design`` is 0) though it is not feasible (a reach or
collision part: the run stopped at its iteration cap), :func:`verification_round`
verifies it on the dense grid (:func:`linkopt._design.verify.verify`, default
resolution). The second case was met by a user: nine samples read no singularity on
a design whose grid had ``f_sing`` 1e5 above ``α₋``, and no round ran because the
design never became feasible; the grid's worst cell is news to the samples whether the
design is feasible or not. Where verification fails, the failing places become IK
targets of the evaluation (each target's IK sample goes there and its adversarial
sample starts there):

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
its last design and says that it is unverified, the round's ``stopped`` saying why.
Every round is recorded (iteration, the design, whether it was feasible, coverage,
worst ``f_sing``, the targets it added); ``summary.json`` lists them.
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
    """Whether ``run`` has finished with a design that no round has verified yet, and
    that is feasible or whose samples show no singularity (module docstring), with
    verification in the loop on."""
    checked = bool(run.rounds) and run.rounds[-1]["iteration"] == run.iteration
    return (
        settings.verify_rounds > 0
        and run.finished
        and (run.result_feasible or samples_clear(run))
        and not checked
    )


def samples_clear(run: SwarmRun) -> bool:
    """Whether the returned design's samples show no singularity: the singularity part
    of its ``f_design`` (the history's last record) is 0."""
    return bool(run.history) and run.history[-1].get("singularity") == 0.0


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


def _record(
    run: SwarmRun, check: Verification, added: list, stopped: str | None
) -> dict:
    """The round's record (module docstring); ``verification`` is what
    ``verification.json`` holds for the design, ``stopped`` why a failed round does
    not go on."""
    record = {
        "round": len(run.rounds),
        "iteration": run.iteration,
        "design": [float(v) for v in best_design(run)],
        "feasible": bool(run.result_feasible),
        "passed": bool(check.passed),
        "coverage": float(check.coverage),
        "max_f_sing": float(check.max_f_sing),
        "threshold": float(check.threshold),
        "added_targets": added,
        "verification": check.as_json(),
    }
    return record if stopped is None else {**record, "stopped": stopped}


def _stop_reason(
    run: SwarmRun, settings: OptimizerSettings, check: Verification, added: list
) -> str | None:
    """Why a round that failed does not go on, or None (it passed, or goes on)."""
    if check.passed:
        return None
    if not added:
        return (
            "its failing places are IK targets already, so more iterations would "
            "score the same targets"
        )
    if len(run.rounds) >= settings.verify_rounds:
        return f"no verification rounds left (--verify-rounds {settings.verify_rounds})"
    return None


def verification_round(
    mech: Mechanism, run: SwarmRun, settings: OptimizerSettings
) -> SwarmRun:
    """Verify the finished ``run``'s design on ``mech`` (the file's mechanism with the
    targets added so far) and record the round; where it fails and the budget allows,
    add the failing places as targets and :func:`reopen` the run, feasible or not."""
    check = verify(mech, best_design(run))
    added = [] if check.passed else failing_places(mech, check)
    reopening = bool(added) and len(run.rounds) < settings.verify_rounds
    stopped = _stop_reason(run, settings, check, added)
    record = _record(run, check, added if reopening else [], stopped)
    run = dataclasses.replace(run, rounds=(*run.rounds, record))
    return reopen(run, settings) if reopening else run
