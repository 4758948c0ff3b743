"""The dense continuation's one loop of linearisations
(:func:`linkopt._engine.continuation.walk`) against the nested walk it replaced (a
step loop around each corrector's own LM loop,
:func:`~linkopt._engine.continuation.nested_walk`, which the band keeps), and the number
of linearisations its programs hold."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import linkopt
from linkopt._engine import continuation, kinematics
from linkopt._engine.constraints import (
    homogenised_motor_values,
    homogenised_output_values,
)
from linkopt._engine.geometry import design_vector, geometry, rest_state

VALUES = {"fk": homogenised_motor_values, "bk": homogenised_output_values}


@pytest.mark.parametrize(
    ("name", "kind", "span"),
    [("five_bar", "fk", 1.2), ("five_bar", "bk", 0.3), ("jansen_2dof", "fk", 0.8)],
)
def test_the_one_loop_walk_takes_the_nested_walks_steps(name, kind, span):
    """Same states, fractions and LM iterations, lane by lane, for rows far enough
    from rest to take several steps and halvings. The nested walk here predicts from
    normal equations made afresh, equal to the carried ones to rounding only, so rows
    whose walk ends short of the way (near a singularity, where halvings go on for
    hundreds of iterations) must end short in both, not after the same iterations."""
    mech = linkopt.load(f"mechanisms/{name}.toml")
    geom = geometry(mech, design_vector(mech, None))
    state = rest_state(mech)
    v0 = VALUES[kind](mech, geom, state)
    rows = v0 + jnp.asarray(
        np.random.default_rng(5).uniform(-span, span, (12, v0.size))
    )

    def both(geom, v0, state, v):  # all traced: the engine's programs nest in it
        fused = continuation.walk(mech, kind, geom, v0, state, v)[:3]
        return fused, continuation.nested_walk(mech, kind, geom, v0, state, v)

    batch = jax.vmap(both, in_axes=(None, None, None, 0))
    (state, fraction, iterations), nested = jax.jit(batch)(geom, v0, state, rows)
    whole = np.asarray(nested[1]) == 1.0
    assert whole.sum() >= 8
    np.testing.assert_array_equal(np.asarray(fraction) == 1.0, whole)
    np.testing.assert_array_equal(iterations[whole], nested[2][whole])
    np.testing.assert_allclose(state[whole], nested[0][whole], rtol=0, atol=1e-11)


def _linearisations(jaxpr) -> int:
    """Calls of the solves' linearisation (a program of its own inside the trace)."""
    count = 0
    for eqn in jaxpr.eqns:
        if eqn.params.get("name") in ("normal_equations", "normal_equations_tail"):
            count += 1
            continue
        for param in eqn.params.values():
            for sub in param if isinstance(param, (list, tuple)) else [param]:
                inner = getattr(sub, "jaxpr", sub)
                if hasattr(inner, "eqns"):
                    count += _linearisations(inner)
    return count


@pytest.mark.parametrize("path", [False, True])
def test_a_walk_program_holds_the_linearisation_twice(five_bar, path):
    """Once for the walk's start and once in its loop (the nested walk held three:
    the start, each corrector's first point and its steps); a path's rows take their
    start from the row before, so its loop holds one too."""
    rows = np.zeros((4, five_bar.num_motors)) + 0.1
    solve = kinematics.solve_fk_path if path else kinematics.solve_fk
    program = lambda v: solve(five_bar, v)  # noqa: E731  (traced: one program)
    assert _linearisations(jax.make_jaxpr(program)(rows).jaxpr) == 2
