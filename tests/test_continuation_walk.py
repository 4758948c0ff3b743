"""The dense continuation's predictions from the normal equations it carries
(:func:`linkopt._engine.continuation.walk`) against a walk that predicts every step
afresh (:func:`~linkopt._engine.continuation.nested_walk`): the same steps, lane by
lane."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from long_linkages import chain

import linkopt
from linkopt._engine import banded, continuation
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
def test_the_carried_walk_takes_the_fresh_walks_steps(name, kind, span):
    """Same states, fractions and LM iterations, lane by lane, for rows far enough
    from rest to take several steps and halvings. The fresh walk predicts from
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
        carried = continuation.walk(mech, kind, geom, v0, state, v)[:3]
        return carried, continuation.nested_walk(mech, kind, geom, v0, state, v)

    batch = jax.vmap(both, in_axes=(None, None, None, 0))
    (state, fraction, iterations), nested = jax.jit(batch)(geom, v0, state, rows)
    whole = np.asarray(nested[1]) == 1.0
    assert whole.sum() >= 8
    np.testing.assert_array_equal(np.asarray(fraction) == 1.0, whole)
    np.testing.assert_array_equal(iterations[whole], nested[2][whole])
    np.testing.assert_allclose(state[whole], nested[0][whole], rtol=0, atol=1e-11)


def _walks(mech, kind: str):
    """A new jitted batch of :func:`continuation.walk` (traced afresh, so it reads
    ``continuation.STEP_ITERATIONS`` as it is now)."""

    def walks(geom, v0, state, rows):
        one = lambda v: continuation.walk(mech, kind, geom, v0, state, v)[:3]  # noqa: E731
        return jax.vmap(one)(rows)

    return jax.jit(walks)


def test_rows_past_the_reach_fail_in_fewer_iterations_and_reached_rows_are_unchanged(
    monkeypatch,
):
    """Five-bar rows within ±1.2 rad of rest, some past its reach: with each step's
    corrector capped at ``STEP_ITERATIONS`` the same rows reach their values, to
    bitwise the same states as with the file's cap (60), in no more LM iterations
    (fewer where a step on the way was rejected: it now gives up sooner); a row that
    stops short stops where it did, in at most half the iterations (measured: about
    270 against 760)."""
    mech = linkopt.load("mechanisms/five_bar.toml")
    assert continuation.STEP_ITERATIONS < mech.solver.max_iterations
    geom = geometry(mech, design_vector(mech, None))
    state = rest_state(mech)
    v0 = homogenised_motor_values(mech, geom, state)
    rows = v0 + jnp.asarray(np.random.default_rng(5).uniform(-1.2, 1.2, (12, 2)))
    capped = [np.asarray(a) for a in _walks(mech, "fk")(geom, v0, state, rows)]
    monkeypatch.setattr(continuation, "STEP_ITERATIONS", mech.solver.max_iterations)
    full = [np.asarray(a) for a in _walks(mech, "fk")(geom, v0, state, rows)]
    whole = full[1] == 1.0
    assert 3 <= (~whole).sum() and whole.sum() >= 6
    np.testing.assert_array_equal(capped[1] == 1.0, whole)
    np.testing.assert_array_equal(capped[0][whole], full[0][whole])
    assert np.all(capped[2][whole] <= full[2][whole])
    np.testing.assert_allclose(capped[1][~whole], full[1][~whole], rtol=0, atol=1e-6)
    np.testing.assert_allclose(capped[0][~whole], full[0][~whole], rtol=0, atol=1e-6)
    assert np.all(2 * capped[2][~whole] <= full[2][~whole])


def _walk_program(mech) -> str:
    """The jaxpr of one FK walk of ``mech`` from rest, as text."""
    geom = geometry(mech, design_vector(mech, None))
    state = rest_state(mech)
    v0 = homogenised_motor_values(mech, geom, state)
    walk = lambda g, v: continuation.walk(mech, "fk", g, v0, state, v)[:3]  # noqa: E731
    return str(jax.make_jaxpr(walk)(geom, v0 + 0.5))


@pytest.mark.parametrize("on_the_band", [False, True])
def test_the_cap_is_the_dense_paths_only(on_the_band, monkeypatch):
    """On the band (long, soft chains: lazy tongs of 300 bodies failed to reach -1 and
    -1.5 rad with the cap) every step keeps the file's iteration cap, so the walk's
    program does not depend on ``STEP_ITERATIONS``; on the dense path it does."""
    bodies = banded.MIN_BODIES + 4 if on_the_band else 6
    mech = linkopt.loads(chain(bodies), "tongs.toml")
    assert banded.serves(mech) == on_the_band
    capped = _walk_program(mech)
    monkeypatch.setattr(continuation, "STEP_ITERATIONS", 1)
    assert (_walk_program(mech) == capped) == on_the_band
