"""The paper's mechanism suite (Sec. VI, Table I): sizes, mobility, targets, and the
defect of each initial design as `verify` sees it.

Verification runs on a coarse grid (13 per output, 7 for three outputs): enough to find
the defects, which span a good part of each range, at test-suite cost.
"""

import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._design.evaluation import alpha_minus, targets
from linkopt._design.verify import verify

# name: |s|, |p|, IK targets, mobility (Table I; the mobility is the number of motors)
TABLE_I = {
    "finger": (49, 12, 9, 2),
    "neck_2dof": (42, 6, 9, 2),
    "jansen_2dof": (63, 12, 16, 2),
    "neck_3dof": (56, 6, 27, 3),
}


@pytest.mark.parametrize("name", sorted(TABLE_I))
def test_sizes_match_table_one(name):
    mech = linkopt.load(MECHANISMS / f"{name}.toml")
    state_size, parameters, target_count, mobility = TABLE_I[name]
    assert mech.state_size == state_size
    assert mech.design.size == parameters
    assert len(targets(mech)) == target_count
    assert linkopt.mobility(mech) == mobility == mech.num_motors == mech.num_outputs


# name: (forward singularity in the range, backward singularity in the range,
#        part unreachable)
DEFECTS = {
    "finger": (True, False, False),
    "neck_2dof": (True, False, False),
    "jansen_2dof": (True, True, True),
    "neck_3dof": (True, False, True),
}


@pytest.mark.parametrize("name", sorted(DEFECTS))
def test_initial_design_fails_verify_for_the_stated_reason(name):
    """A singularity's side of f_sing = 1/σ_FK + 1/σ_BK alone exceeds α₋ exactly where
    the file's header says the design has that singularity; coverage below 1 where it
    says part of the range is out of reach."""
    mech = linkopt.load(MECHANISMS / f"{name}.toml")
    forward, backward, unreachable = DEFECTS[name]
    result = verify(mech, resolution=13 if mech.num_outputs == 2 else 7)
    assert not result.passed
    assert result.threshold == pytest.approx(alpha_minus(mech))
    assert (1.0 / result.min_sigma_fk > result.threshold) == forward, result
    assert (1.0 / result.min_sigma_bk > result.threshold) == backward, result
    assert (result.coverage < 1.0) == unreachable, result
