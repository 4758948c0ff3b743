"""The least-squares polish of a synthesis (:mod:`linkopt._synth.polish`): its
residuals, and on the spatial RSSR function generator (3 parameters) a polish from
the file's design, which misses its targets by more than 3 tolerances, that meets
them and stays in the design bounds."""

from __future__ import annotations

import numpy as np
from conftest import MECHANISMS

import linkopt
from linkopt._design.evaluation import alpha_minus
from linkopt._synth import polish as polishing
from linkopt._synth.objective import Problem, plan, score
from linkopt._synth.targets import targets_of


def test_residuals_charge_a_target_again_past_the_margin():
    d = np.array([[0.0, 0.5, 0.6, 1.0, np.nan]])
    r = polishing.residuals(d, tolerance=1.0)
    np.testing.assert_allclose(r[0, :5], [0.0, 0.5, 0.6, 1.0, 100.0])
    extra = polishing.WEIGHT * np.array([0.0, 0.0, 0.0, 0.4, 99.4])
    np.testing.assert_allclose(r[0, 5:], extra, atol=1e-12)


def test_difference_steps_stay_in_the_bounds():
    lower, upper = np.zeros(3), np.ones(3)
    p = np.array([0.0, 0.5, 1.0])
    h = polishing.difference_steps(p, lower, upper)
    assert np.all(p + h >= lower) and np.all(p + h <= upper) and np.all(h != 0)


def test_polish_meets_the_rssr_targets_from_the_file_design():
    mech = linkopt.load(MECHANISMS / "rssr.toml")
    targets = targets_of(mech)
    problem = Problem(targets, plan(mech, targets, 120, None))
    alpha = alpha_minus(mech)
    start = mech.design.p0
    fine = polishing.polish(mech, problem, start, alpha, batch=4, evaluations=25)
    assert np.all(fine >= mech.design.lower) and np.all(fine <= mech.design.upper)
    before, after = (
        np.asarray(score(mech, problem, np.stack([start, fine] * 2), alpha).distances)
    )[:2]
    assert before.max() > 3 * targets.tolerance
    assert after.max() <= targets.tolerance
    assert np.sqrt(np.mean(after**2)) < 0.2 * np.sqrt(np.mean(before**2))
