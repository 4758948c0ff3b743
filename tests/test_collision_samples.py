"""Collision samples (issue 30): with ``[collision]`` enabled, each target's IK sample
is followed by a search for the pose of least clearance near it (the adversarial
sampler with another objective, :func:`linkopt._design.objectives.clearance_objective`).

* each collision sample is no clearer than its IK sample, lies in the target range,
  and the least clearance over them is the least that ``verify``'s dense grid finds;
* from a clear IK sample next to the colliding part of the range, the search finds
  the collision, so ``f_design`` counts it where the IK samples alone would not;
* ``f_design``'s collision part is ``weight · ½ (c(s_IK) + c(s_col))``;
* a file without ``[collision]`` has no collision samples.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import linkopt
from linkopt._design.evaluation import evaluate
from linkopt._design.verify import verify
from linkopt._engine.readout import output_values

ROOT = Path(__file__).resolve().parents[1]
LIFTED = ROOT / "mechanisms" / "four_bar_collision.toml"


def _least(mech, states, design) -> np.ndarray:
    return linkopt.clearance(mech, np.asarray(states), design=design).minimum


@pytest.mark.parametrize("lift", [0.0, -3.0, -5.0])
def test_collision_samples_find_the_least_clearance(lift):
    mech = linkopt.load(LIFTED)
    design = np.array([lift])
    ev = evaluate(mech, design)
    ik = _least(mech, ev.ik_states, design)
    col = _least(mech, ev.col_states, design)
    assert np.all(col <= ik + 1e-9)
    outputs = np.asarray(output_values(mech, ev.col_states, design=design))
    slack = 1e-3 * (mech.output_max - mech.output_min)
    assert np.all(outputs >= mech.output_min - slack)
    assert np.all(outputs <= mech.output_max + slack)
    dense = verify(mech, design, resolution=41).min_clearance
    assert np.min(col) == pytest.approx(dense, abs=0.05)
    # the first target's IK sample (the rocker's lower end) is clear by 0.4-3 mm more
    # than the collision sample the search found from it
    assert col[0] < ik[0] - 0.4
    values = (
        linkopt.clearance(mech, np.asarray(ev.ik_states), design=design).value
        + linkopt.clearance(mech, np.asarray(ev.col_states), design=design).value
    )
    share = float(ev.f_design - ev.reach - ev.singularity)
    expected = mech.collision.weight * 0.5 * np.mean(values)
    assert share == pytest.approx(expected, rel=1e-9, abs=1e-15)


def test_a_collision_next_to_a_clear_target_counts_in_f_design():
    """The colliding four-bar: at the rocker's lower end the links are apart (0.44
    mm, inside the band), but the coupler crosses the ground link a little above it;
    that target's collision sample finds the crossing (clearance -3.2), so its summand
    has the barrier at contact and more, where the IK sample's is below 1."""
    mech = linkopt.load(LIFTED)
    ev = evaluate(mech)
    first_ik = linkopt.clearance(mech, np.asarray(ev.ik_states)[:1]).value[0]
    first_col = linkopt.clearance(mech, np.asarray(ev.col_states)[:1]).value[0]
    assert first_col > 1.0 > first_ik


def test_no_collision_samples_without_collision():
    off = linkopt.loads(
        LIFTED.read_text().replace("enable = true", "enable = false"), "off.toml"
    )
    ev = evaluate(off)
    assert ev.col_motors is None and ev.col_states is None
