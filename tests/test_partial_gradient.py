"""The partial gradient of a mechanism with joints that have no axis (ball joints).

Regression: the geometry's unit vectors divided by a norm whose square root was taken
at zero for an unused axis (a ball joint's, or the second axis of any joint but a
universal one). A zero cotangent then met ``d sqrt(0) = inf`` and the partial
gradient of every mechanism with a ball joint was NaN (``mechanisms/delta.toml``:
``[nan, nan]``), so the optimiser ran on the swarm alone.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._design.evaluation import alpha_minus, evaluate
from linkopt._design.partial import frozen_objective, partial_gradient
from linkopt._engine.geometry import geometry

# A spatial RSSR four-bar: crank and rocker on revolute joints about z, coupler on
# two ball joints (its spin about B-C is idle), the design the rocker pivot's x.
RSSR = """
[mechanism]
name = "RSSR"
ground = "ground"
[[bodies]]
name = "ground"
[[bodies]]
name = "crank"
[[bodies]]
name = "coupler"
[[bodies]]
name = "rocker"
[[joints]]
name = "A"
type = "revolute"
bodies = ["ground", "crank"]
anchor = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "B"
type = "spherical"
bodies = ["crank", "coupler"]
anchor = [20.0, 0.0, 0.0]
[[joints]]
name = "C"
type = "spherical"
bodies = ["coupler", "rocker"]
anchor = [51.25, 39.03123748998999, 0.0]
[[joints]]
name = "D"
type = "revolute"
bodies = ["ground", "rocker"]
anchor = [60.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[motors]]
name = "crank"
joint = "A"
[[outputs]]
name = "rocker"
joint = "D"
min = -0.08
max = 0.3
[evaluation]
samples_per_dimension = 3
ik_iterations = 10
adversarial_iterations = 10
[[parameters]]
name = "pivot"
joint = "D"
coordinate = "x"
min = 55.0
max = 65.0
"""


# an unused second axis (five-bar), ball joints (delta), universal and ball joints
@pytest.mark.parametrize("name", ["five_bar", "delta", "stewart"])
def test_geometry_pulls_back_any_cotangent_to_a_finite_gradient(name):
    mech = linkopt.load(MECHANISMS / f"{name}.toml")
    design = jnp.asarray(mech.design.p0)

    # jitted, one program for both cotangents (op by op: about a hundred compilations)
    @jax.jit
    def pulled_back(cotangent):
        _, pullback = jax.vjp(lambda p: geometry(mech, p), design)
        return pullback(cotangent)

    rest = geometry(mech, design)
    for cotangent in (jax.tree_util.tree_map(jnp.zeros_like, rest), rest):
        (gradient,) = pulled_back(cotangent)
        assert np.all(np.isfinite(np.asarray(gradient)))


def test_partial_gradient_with_ball_joints_matches_finite_differences():
    mech = linkopt.loads(RSSR)
    alpha = alpha_minus(mech)
    p = np.array([61.0])
    ev = jax.tree_util.tree_map(np.asarray, evaluate(mech, p))
    gradient = np.asarray(partial_gradient(mech, p, ev, alpha))
    objective = jax.jit(
        functools.partial(frozen_objective, mech, evaluation=ev, alpha=alpha)
    )
    h = 1e-4
    fd = (objective(p + h) - objective(p - h)) / (2 * h)
    assert np.all(np.isfinite(gradient)) and abs(float(fd)) > 1e-6
    np.testing.assert_allclose(gradient, [fd], rtol=1e-4)
