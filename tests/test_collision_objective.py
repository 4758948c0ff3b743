"""The collision term in the design loop (issue 30, second part): ``f_design``, the
partial gradient, verification rounds and ``optimize``.

* with ``[collision]`` enabled, ``f_design - reach - singularity`` is ``weight`` times
  the collision term that ``evaluate`` reports (the mean over the IK and collision
  sample states), proportional to the weight; switched off, ``f_design`` is
  ``reach + singularity`` and the samples are the same;
* the partial gradient of the collision four-bar (design parameters lifting the
  coupler out of the plane and moving the ground pivot D) matches central
  differences of the frozen objective, and the collision term's pull is in it;
* a verification that fails on a collision adds the cell of least clearance as an IK
  target, and the run goes on;
* a small optimisation of a colliding four-bar with a design parameter that can clear
  it ends with a larger least clearance than the initial design's.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import jax
import numpy as np
import pytest

import linkopt
from linkopt._design.evaluation import alpha_minus, evaluate, targets
from linkopt._design.optimizer import OptimizerSettings, best_design
from linkopt._design.partial import frozen_objective, partial_gradient
from linkopt._design.rounds import collided, failing_places, with_targets
from linkopt._design.run import optimize
from linkopt._design.verify import verify
from linkopt._engine.collision import clearance

DATA = Path(__file__).parent / "data"
COLLIDING = DATA / "four_bar_collision.toml"

#: A design parameter on the collision four-bar: the ground pivot D's x.
D_X = """
[[parameters]]
name = "d_x"
joint = "D"
coordinate = "x"
min = 55.0
max = 65.0
"""
#: A design parameter that lifts the coupler out of the plane: joints B and C move
#: along their (parallel) axes together, so the motion is that of the file's four-bar
#: and only the coupler's distance to the ground link changes: its capsule clears the
#: ground's (radii 1.6 each, clearance 1.6) from a lift of 4.8 on, up or down.
LIFT = """
[[parameters]]
name = "lift"
joint = "B"
coordinate = "z"
min = -20.0
max = 20.0
ties = [{ joint = "C", coordinate = "z", factor = 1.0 }]
"""
#: A rocker angle inside the colliding part of the range and between the grid's
#: targets (-0.08, 0.11, 0.3): the coupler's projection crosses the ground link.
COLLIDING_PLACE = [0.2]


def _text(extra: str = "", replace: tuple[str, str] | None = None) -> str:
    text = COLLIDING.read_text()
    if replace:
        assert replace[0] in text
        text = text.replace(*replace, 1)
    return text + "\n" + extra


def _load(extra: str = "", replace: tuple[str, str] | None = None, name="c.toml"):
    return linkopt.loads(_text(extra, replace), name)


def _term(mech, ev) -> float:
    """The collision term ``evaluate`` reports: the barrier's mean over the IK and
    collision sample states."""
    states = np.concatenate([np.asarray(ev.ik_states), np.asarray(ev.col_states)])
    return float(np.mean(clearance(mech, states).value))


# --- f_design -----------------------------------------------------------------------


@pytest.fixture(scope="module")
def colliding():
    """The collision four-bar and its evaluation, shared by the tests that read it."""
    mech = linkopt.load(COLLIDING)
    return mech, evaluate(mech)


def test_f_design_gains_the_weighted_collision_term(colliding):
    mech, ev = colliding
    term = _term(mech, ev)
    assert term > 0.0  # the coupler sweeps through the ground link
    share = float(ev.f_design - ev.reach - ev.singularity)
    assert share == pytest.approx(mech.collision.weight * term, rel=1e-9)
    # the samples do not depend on the weight, the share does, in proportion
    heavy = _load(replace=("weight = 1.0", "weight = 3.0"))
    ev3 = evaluate(heavy)
    np.testing.assert_array_equal(ev3.ik_states, ev.ik_states)
    np.testing.assert_array_equal(ev3.adv_states, ev.adv_states)
    share3 = float(ev3.f_design - ev3.reach - ev3.singularity)
    assert share3 == pytest.approx(3.0 * share, rel=1e-9)


def test_switched_off_collision_leaves_f_design_as_reach_plus_singularity(colliding):
    _, ev = colliding
    off = _load(replace=("enable = true", "enable = false"))
    ev_off = evaluate(off)
    np.testing.assert_array_equal(ev_off.ik_states, ev.ik_states)
    np.testing.assert_array_equal(ev_off.adv_states, ev.adv_states)
    assert float(ev_off.reach) == float(ev.reach)
    assert float(ev_off.singularity) == float(ev.singularity)
    assert float(ev_off.f_design) == pytest.approx(
        float(ev_off.reach + ev_off.singularity), rel=1e-12
    )
    assert float(ev.f_design) > float(ev_off.f_design)


def test_evaluate_command_shows_the_share(colliding):
    from linkopt._cli.evaluation import evaluation_payload

    mech, ev = colliding
    entry = evaluation_payload(mech, ev)["collision"]
    assert entry["share"] == pytest.approx(
        float(ev.f_design - ev.reach - ev.singularity), rel=1e-9
    )


# --- the partial gradient -----------------------------------------------------------


@functools.cache
def _frozen(mech):
    return jax.jit(lambda p, ev: frozen_objective(mech, p, ev, alpha_minus(mech)))


def test_partial_gradient_with_the_collision_term_matches_finite_differences():
    """Lifts of 2 to 3.5 (the coupler in the band over the ground link where their
    projections cross) and four positions of the pivot D. Four designs: the batch of
    the optimiser's four particles below (the same structure, its one parameter
    padded as these two are), so both tests run one evaluation and one gradient
    program."""
    mech = _load(LIFT + D_X, name="lift.toml")
    alpha = alpha_minus(mech)
    designs = np.array([[2.0, 60.0], [3.0, 61.5], [2.5, 59.0], [3.5, 62.5]])
    ev = jax.tree_util.tree_map(np.asarray, evaluate(mech, designs))
    assert np.all(ev.f_design - ev.reach - ev.singularity > 0.0)  # in the band
    assert np.all(ev.reach < 1e-12) and np.all(ev.singularity == 0.0)
    gradients = np.asarray(partial_gradient(mech, designs, ev, alpha))
    for i, p in enumerate(designs):
        one = jax.tree_util.tree_map(lambda x, i=i: x[i], ev)
        objective = functools.partial(_frozen(mech), ev=one)
        # the frozen objective at the evaluated design is the evaluation itself
        assert float(objective(p)) == pytest.approx(
            float(ev.f_design[i] + ev.regularizer[i]), rel=1e-8
        )
        h = 1e-5
        fd = [
            (objective(p + h * e) - objective(p - h * e)) / (2 * h)
            for e in np.eye(p.size)
        ]
        np.testing.assert_allclose(
            gradients[i], fd, rtol=1e-4, atol=2e-5 * np.max(np.abs(fd))
        )
        # the collision term is in it: reach and singularity are zero here, and the
        # regulariser alone would pull the lift back to 0 (a positive slope)
        assert gradients[i, 0] < 0.0


# --- verification rounds ------------------------------------------------------------


def test_a_collision_found_by_verify_becomes_an_ik_target():
    """The collision four-bar fails verify on a collision; its cell of least clearance
    is a failing place unless it is a target already (here the box's end, the grid's
    first target), and a cell between the targets is added."""
    mech = linkopt.load(COLLIDING)
    check = verify(mech, resolution=9)
    assert check.coverage == 1.0 and check.max_f_sing < check.threshold
    assert collided(mech, check) and not check.passed
    known = targets(mech)
    cell = np.asarray(check.collision_outputs)
    is_target = np.any(np.all(np.isclose(known, cell, rtol=0, atol=1e-12), axis=1))
    assert failing_places(mech, check) == ([] if is_target else [cell.tolist()])
    between = np.array([0.5 * (known[0, 0] + known[1, 0])])
    moved = dataclasses.replace(check, collision_outputs=between)
    assert failing_places(mech, moved) == [between.tolist()]
    # a clear verification adds nothing for collisions
    clear = dataclasses.replace(check, min_clearance=2.0 * mech.collision.clearance)
    assert not collided(mech, clear) and failing_places(mech, clear) == []


def test_an_added_collision_target_counts_in_f_design():
    """A target added inside the colliding part of the range: its IK sample collides,
    and f_design's collision share counts it."""
    mech = linkopt.load(COLLIDING)
    place = COLLIDING_PLACE
    more = with_targets(mech, [place])
    ev = evaluate(more)
    states = np.asarray(ev.ik_states)[-1:]
    assert clearance(more, states).value[0] > 0.0
    assert float(ev.f_design - ev.reach - ev.singularity) == pytest.approx(
        _term(more, ev), rel=1e-9
    )


# --- optimize -----------------------------------------------------------------------


def test_optimize_lifts_the_coupler_out_of_collision(tmp_path):
    """The colliding four-bar with the lift parameter: a few particles and iterations
    find a design whose least clearance on verify's grid is larger than the initial
    design's (the coupler through the ground link), clear of the band, and verified."""
    mech = _load(LIFT, name="lift.toml")
    # seed 0 draws the other three particles 2.8, 5.5 and 5.8 below p0 = 0
    settings = OptimizerSettings(particles=4, iterations=3, seed=0, spread=0.15)
    before = verify(mech, resolution=9)
    assert not before.passed and before.min_clearance < 0.0
    run = optimize(mech, tmp_path / "run", settings)
    design = best_design(run)
    after = verify(mech, design, resolution=9)
    assert after.min_clearance > before.min_clearance
    assert run.result_feasible and after.passed
    assert after.min_clearance >= mech.collision.clearance
    assert run.rounds and run.rounds[-1]["passed"]
    _check_history_columns(mech, tmp_path / "run" / "history.csv")


def _check_history_columns(mech, path: Path) -> None:
    """``history.csv`` of a file with ``[collision]``: ``collision`` is the running
    best's ``f_design - reach - singularity``, and it is zero exactly when that
    design's least sample clearance is clear of the band (the barrier's zero set)."""
    rows = np.genfromtxt(path, delimiter=",", names=True)
    assert rows.dtype.names[-2:] == ("collision", "min_clearance")
    parts = rows["best_f_design"] - rows["reach"] - rows["singularity"]
    np.testing.assert_allclose(rows["collision"], parts, rtol=1e-9, atol=1e-15)
    clear = rows["min_clearance"] >= mech.collision.clearance
    np.testing.assert_array_equal(rows["collision"] <= 1e-15, clear)
    assert clear[-1]
