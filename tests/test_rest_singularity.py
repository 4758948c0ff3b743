"""A rest pose near a singularity (issue 20, part 5): ``check`` warns, α₋ is not
derived from it unless the file sets ``alpha_minus``; the rest pose's textbook
Jacobian ``∂b/∂a`` against the five-bar's closed form."""

import dataclasses
import json

import numpy as np
import pytest
from conftest import MECHANISMS
from five_bar_closed_form import forward

import linkopt
from linkopt._cli.main import main
from linkopt._design.conditioning import (
    NEAR_SINGULAR_SIGMA,
    alpha_minus,
    rest_conditioning,
)
from linkopt._design.evaluation import evaluate
from linkopt._errors import MechanismFileError

FIVE_BAR = (MECHANISMS / "five_bar.toml").read_text()
TIP = "anchor = [0.0, 70.0, 0.0]"
FACTOR = "alpha_factor = 3.0"


def near_singular(tmp_path, gap: float, alpha: str = ""):
    """The five-bar with its tip ``gap`` mm above the elbows' line: the distal links
    are nearly collinear, a forward singularity at ``gap`` = 0; ``alpha`` replaces
    its ``[evaluation]`` line ``alpha_factor = 3.0``."""
    assert FIVE_BAR.count(TIP) == 1 and FIVE_BAR.count(FACTOR) == 1
    text = FIVE_BAR.replace(TIP, f"anchor = [0.0, {36.0 + gap}, 0.0]")
    text = text.replace(FACTOR, alpha or FACTOR)
    path = tmp_path / f"near_{gap:g}.toml"
    path.write_text(text)
    return path


def test_textbook_jacobian_matches_the_closed_form(five_bar):
    rest = rest_conditioning(five_bar)
    h = 1e-6
    numeric = np.stack(
        [
            (forward(h * e) - forward(-h * e))[0] / (2 * h)
            for e in np.eye(2)  # motor i
        ],
        axis=1,
    )
    expected = np.linalg.svd(numeric, compute_uv=False)
    np.testing.assert_allclose(rest.jacobian_sigmas, expected, rtol=1e-6)
    assert not rest.near_singular and rest.f_sing == pytest.approx(
        1 / rest.sigma_fk + 1 / rest.sigma_bk
    )


def test_near_singular_rest_scales_with_the_gap(tmp_path):
    """σ_min FK vanishes linearly with the gap to collinearity, and the textbook
    Jacobian's largest singular value grows as its inverse."""
    a = rest_conditioning(linkopt.load(near_singular(tmp_path, 1e-2)))
    b = rest_conditioning(linkopt.load(near_singular(tmp_path, 1e-3)))
    assert a.near_singular and b.near_singular
    assert a.sigma_fk < NEAR_SINGULAR_SIGMA and a.sigma_bk > 0.1
    assert a.sigma_fk / b.sigma_fk == pytest.approx(10.0, rel=1e-3)
    assert b.jacobian_sigmas[0] / a.jacobian_sigmas[0] == pytest.approx(10, rel=1e-3)


def test_alpha_minus_is_not_derived_from_a_near_singular_rest_pose(tmp_path):
    mech = linkopt.load(near_singular(tmp_path, 1e-2))
    with pytest.raises(MechanismFileError, match=r"set \[evaluation\] alpha_minus"):
        alpha_minus(mech)
    with pytest.raises(MechanismFileError, match="near a forward singularity"):
        evaluate(mech)
    fixed = linkopt.load(near_singular(tmp_path, 1e-2, "alpha_minus = 30.0"))
    assert alpha_minus(fixed) == 30.0


def test_evaluate_command_refuses_in_one_line(tmp_path, capsys):
    assert main(["evaluate", str(near_singular(tmp_path, 1e-2))]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "alpha_minus" in err


def test_check_warns_but_passes(tmp_path, capsys):
    path = near_singular(tmp_path, 1e-2)
    assert main(["check", str(path)]) == 0
    captured = capsys.readouterr()
    assert "OK with 1 warning(s)" in captured.out and "rest pose" in captured.out
    assert "linkopt: warning:" in captured.err
    assert "near a forward singularity" in captured.err
    assert "set [evaluation] alpha_minus" in captured.err
    assert main(["check", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["rest_pose"]["near_singular"] and len(info["warnings"]) == 1
    assert info["rest_pose"]["sigma_min_fk"] < NEAR_SINGULAR_SIGMA


def test_check_of_a_shipped_file_has_no_warning(capsys):
    assert main(["check", str(MECHANISMS / "five_bar.toml"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["warnings"] == [] and not info["rest_pose"]["near_singular"]
    assert info["rest_pose"]["f_sing"] == pytest.approx(8.0128, rel=1e-3)


def test_optimize_refuses_before_any_work(tmp_path):
    from linkopt._design.optimizer import OptimizerSettings
    from linkopt._design.run import optimize

    mech = linkopt.load(near_singular(tmp_path, 1e-2))
    settings = OptimizerSettings(particles=2, iterations=1, seed=0)
    with pytest.raises(MechanismFileError, match="alpha_minus"):
        optimize(mech, tmp_path / "run", settings)
    assert not (tmp_path / "run").exists()


def test_a_nan_sigma_min_is_refused_not_let_through(five_bar, monkeypatch):
    """Regression: the rest-pose guard compared ``sigma < tol``, which NaN passes."""
    from linkopt._design.conditioning import RestConditioning
    from linkopt._engine import mobility

    real = mobility.rest_jacobians(five_bar)

    def with_sigmas(*sigmas):
        return lambda mech: dataclasses.replace(real, sigmas=np.array(sigmas))

    monkeypatch.setattr(mobility, "rest_jacobians", with_sigmas(np.nan, 1.0))
    with pytest.raises(linkopt.MechanismFileError, match="forward singularity"):
        mobility.check_mobility(five_bar)
    monkeypatch.setattr(mobility, "rest_jacobians", with_sigmas(1.0, np.nan))
    with pytest.raises(linkopt.MechanismFileError, match="backward singularity"):
        mobility.check_mobility(five_bar)
    assert RestConditioning(1.0, float("nan"), np.ones(2)).near_singular
    assert RestConditioning(float("nan"), 1.0, np.ones(2)).near_singular
