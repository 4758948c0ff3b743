"""Every shipped mechanism computes what it computed before its numbers became program
arguments (``linkopt._engine.lifting``): FK states, output values and σ_min at a few
motor rows, and the five-bar's evaluation, against ``tests/data/reference_values.json``
(written by ``tests/data/make_reference_values.py`` at the commit before the change).

Tolerances: a number taken as an argument instead of a constant may round differently
where XLA folded constants before (a few ulp); the solves and σ_min then agree to
1e-10 (states are homogenised, σ_min relative), and the evaluation, whose capped
minimisations amplify rounding, to 1e-8 relative in f_design and every sample's f_sing.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt

REFERENCE = json.loads(
    (Path(__file__).parent / "data" / "reference_values.json").read_text()
)
SHIPPED = sorted(p.stem for p in MECHANISMS.glob("*.toml"))


def test_every_shipped_mechanism_has_a_reference():
    assert set(SHIPPED) <= set(REFERENCE)


@pytest.mark.parametrize("name", SHIPPED)
def test_fk_outputs_and_sigma_min_are_unchanged(name):
    mech = linkopt.load(MECHANISMS / f"{name}.toml")
    ref = REFERENCE[name]
    solution = linkopt.solve_fk(mech, np.array(ref["motors"]))
    assert np.asarray(solution.converged).tolist() == ref["converged"]
    np.testing.assert_allclose(solution.state, ref["states"], rtol=0, atol=1e-10)
    outputs = np.asarray(linkopt.output_values(mech, solution.state))
    scale = np.asarray(mech.output_scale)
    np.testing.assert_allclose(outputs / scale, np.array(ref["outputs"]) / scale,
                               rtol=0, atol=1e-10)  # fmt: skip
    sigmas = np.asarray(linkopt.singular_values(mech, solution.state))
    np.testing.assert_allclose(sigmas, ref["sigmas"], rtol=1e-10, atol=0)


def test_five_bar_evaluation_is_unchanged(five_bar_evaluation):
    ref = REFERENCE["five_bar_evaluation"]
    ev = five_bar_evaluation
    assert float(ev.f_design) == pytest.approx(ref["f_design"], rel=1e-8)
    np.testing.assert_allclose(ev.ik_f_sing, ref["ik_f_sing"], rtol=1e-8)
    np.testing.assert_allclose(ev.adv_f_sing, ref["adv_f_sing"], rtol=1e-8)
