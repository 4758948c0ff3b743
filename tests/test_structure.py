"""The mechanism as a pytree (``linkopt._engine.structure``): its numbers are leaves,
its Structure (value-equal, no numbers, no names) the rest, so a jitted engine
function is traced once per structure and computes with each mechanism's numbers."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS
from test_lifting import edited_five_bar

import linkopt
from linkopt._engine import constraints, singularity
from linkopt._engine.geometry import geometry, rest_state
from linkopt._engine.structure import Structure, structure

MOTORS = np.array([0.2, -0.1])


@pytest.fixture
def traces(monkeypatch):
    """Counts the traces of :func:`constraints.fk_residual` (a jitted engine
    function) by a side effect of the function it calls while tracing."""
    count = []
    real = constraints.passive_residual

    def counting(*args):
        count.append(1)
        return real(*args)

    monkeypatch.setattr(constraints, "passive_residual", counting)
    jax.clear_caches()
    yield count
    jax.clear_caches()


def residual(mech, state):
    return np.asarray(constraints.fk_residual(mech, geometry(mech), MOTORS, state))


def test_two_loads_equal_structures_and_one_trace(traces):
    first = linkopt.load(MECHANISMS / "five_bar.toml")
    second = linkopt.load(MECHANISMS / "five_bar.toml")
    assert first is not second
    assert structure(first) == structure(second)
    assert hash(structure(first)) == hash(structure(second))
    state = rest_state(first)
    np.testing.assert_array_equal(residual(first, state), residual(second, state))
    assert len(traces) == 1


def test_edited_numbers_share_the_trace_and_compute_with_their_own(traces):
    five_bar = linkopt.load(MECHANISMS / "five_bar.toml")
    edited = edited_five_bar()
    assert structure(edited) == structure(five_bar)
    state = linkopt.solve_fk(edited, MOTORS).state
    jax.clear_caches()
    traces.clear()
    own = residual(edited, state)
    other = residual(five_bar, state)
    assert len(traces) == 1
    assert np.max(np.abs(own)) < 1e-10  # the state closes the edited file's loops
    assert np.max(np.abs(other)) > 1e-3  # and not the five-bar's


@pytest.mark.parametrize(
    "other",
    [
        lambda m: linkopt.load(MECHANISMS / "four_bar.toml"),
        lambda m: dataclasses.replace(
            m, joint_types=("revolute",) * 4 + ("spherical",)
        ),
        lambda m: dataclasses.replace(
            m, joint_bodies=m.joint_bodies[[1, 0, 2, 3, 4]].copy()
        ),
        lambda m: dataclasses.replace(
            m, evaluation=dataclasses.replace(m.evaluation, samples_per_dimension=4)
        ),
    ],
    ids=["another file", "another joint family", "other bodies", "another grid"],
)
def test_another_structure_is_not_equal(five_bar, other):
    assert structure(other(five_bar)) != structure(five_bar)


def test_the_structure_holds_no_numbers_and_no_names(five_bar):
    template = structure(five_bar).template
    assert isinstance(template.anchors, str) and "(5, 3)" in template.anchors
    assert template.joint_names == ("",) * 5
    assert template.name == template.source == "" and template.raw is None
    leaves, treedef = jax.tree_util.tree_flatten(five_bar)
    assert isinstance(treedef.node_data()[1], Structure)
    assert any(np.array_equal(leaf, five_bar.anchors) for leaf in leaves)


def test_a_program_never_sees_another_mechanisms_names(five_bar):
    renamed = dataclasses.replace(
        five_bar,
        name="other",
        joint_names=tuple(f"{n}_x" for n in five_bar.joint_names),
        anchors=five_bar.anchors + 1.0,
    )
    seen = []

    @jax.jit
    def total(mech):
        seen.append((mech.name, mech.joint_names, mech.design.names))
        return jnp.sum(mech.anchors)

    assert float(total(five_bar)) == pytest.approx(np.sum(five_bar.anchors))
    assert float(total(renamed)) == pytest.approx(np.sum(renamed.anchors))
    assert len(seen) == 1  # one trace for both
    name, joints, design = seen[0]
    assert name == "" and set(joints) == {""} and set(design) == {""}


def test_gradient_through_a_jitted_function_wrt_anchors(five_bar):
    """``d (w · C_FK) / d anchors`` at a solved pose, through the jitted
    :func:`constraints.fk_residual`, against central differences (the residual
    is a closed-form function of the anchors)."""
    state = linkopt.solve_fk(five_bar, MOTORS).state
    weights = np.random.default_rng(0).normal(size=residual(five_bar, state).shape)

    def weighted(anchors):
        mech = dataclasses.replace(five_bar, anchors=anchors)
        rows = constraints.fk_residual(mech, geometry(mech), MOTORS, state)
        return jnp.dot(weights, rows)

    anchors = jnp.asarray(five_bar.anchors)
    gradient = np.asarray(jax.grad(weighted)(anchors))
    assert np.max(np.abs(gradient)) > 1e-3
    step = 1e-4
    for joint, coord in ((0, 0), (1, 1), (2, 1), (3, 0), (4, 0), (4, 1)):
        bump = np.zeros_like(five_bar.anchors)
        bump[joint, coord] = step
        fd = (weighted(anchors + bump) - weighted(anchors - bump)) / (2 * step)
        np.testing.assert_allclose(gradient[joint, coord], fd, rtol=1e-6, atol=1e-9)


def test_sigma_min_is_differentiable_in_the_anchors(five_bar):
    """``d f_sing / d anchors`` at the rest pose through the jitted
    :func:`singularity.f_sing_value`: the derivative of the iterated singular
    vectors agrees with central differences to 1e-4 (6e-6 seen)."""
    state = rest_state(five_bar)

    def f_sing(anchors):
        mech = dataclasses.replace(five_bar, anchors=anchors)
        return singularity.f_sing_value(mech, geometry(mech), state)

    anchors = jnp.asarray(five_bar.anchors)
    gradient = np.asarray(jax.grad(f_sing)(anchors))
    step = 1e-3
    for joint, coord in ((0, 0), (4, 1)):
        bump = np.zeros_like(five_bar.anchors)
        bump[joint, coord] = step
        fd = (f_sing(anchors + bump) - f_sing(anchors - bump)) / (2 * step)
        np.testing.assert_allclose(gradient[joint, coord], fd, rtol=1e-4)


def test_a_stored_program_never_sees_names(five_bar, monkeypatch):
    """A program of :func:`programs.call` is traced from the mechanism's Structure:
    blank names, its own numbers. Traced here, not read from the disk cache (where an
    earlier run of the suite left it, and nothing would be traced to look at)."""
    from linkopt._engine import programs

    monkeypatch.setattr(programs, "traces_folder", lambda: None)
    monkeypatch.setattr(programs, "PROGRAMS", {})
    renamed = dataclasses.replace(
        five_bar,
        name="renamed_five_bar",
        motor_names=("left", "right"),
        anchors=five_bar.anchors * 2.0,
    )
    seen = []

    def total(mech, x):
        seen.append((mech.name, mech.motor_names, mech.joint_names))
        return jnp.sum(mech.anchors) * x

    one = jnp.ones(())
    ours = programs.call("names_test", five_bar, total, one)
    theirs = programs.call("names_test", renamed, total, one)
    assert float(theirs) == pytest.approx(2.0 * float(ours))
    assert float(ours) == pytest.approx(np.sum(five_bar.anchors))
    assert seen and all(
        name == "" and set(motors) == {""} and set(joints) == {""}
        for name, motors, joints in seen
    )


def test_vmap_over_mechanisms_of_one_structure(five_bar):
    """A batch of mechanisms (stacked numbers, one Structure) maps like any pytree:
    each lane computes with its own anchors."""
    edited = edited_five_bar()
    batch = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), five_bar, edited)
    sums = jax.vmap(lambda m: jnp.sum(m.anchors))(batch)
    np.testing.assert_allclose(sums, [np.sum(five_bar.anchors), np.sum(edited.anchors)])
    spread = jax.vmap(lambda m, x: jnp.sum(m.anchors) * x, in_axes=(None, 0))
    np.testing.assert_allclose(
        spread(five_bar, jnp.arange(2.0)), [0.0, np.sum(five_bar.anchors)]
    )


def test_a_mechanism_of_jax_arrays_flattened_inside_a_trace_keeps_no_tracer(five_bar):
    """A concrete mechanism whose fields are JAX arrays (as the DH arms build them),
    first flattened inside a trace, is cached with concrete numbers: a later trace
    of another function computes with them (regression: a float32 field converted
    by ``jax.numpy`` inside the first trace was kept as that trace's tracer)."""
    arrays = dataclasses.replace(
        five_bar,
        anchors=jnp.asarray(five_bar.anchors, dtype=jnp.float32),
        length_scale=jnp.asarray(five_bar.length_scale),
    )
    first = jax.jit(lambda x: jax.tree_util.tree_leaves(arrays)[1].sum() * x)(1.0)
    again = jax.jit(lambda m, x: jnp.sum(m.anchors) * x)(arrays, 2.0)
    np.testing.assert_allclose(again, 2.0 * first, rtol=1e-6)
    leaves = jax.tree_util.tree_leaves(arrays)
    assert not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def test_gradient_through_a_solve_wrt_anchors(five_bar):
    """``d s / d anchors`` of an FK solve (the implicit derivative, carried
    through the geometry) against central differences."""

    def solved(anchors):
        mech = dataclasses.replace(five_bar, anchors=anchors)
        return linkopt.solve_fk(mech, MOTORS).state

    anchors = jnp.asarray(five_bar.anchors)
    bump = np.zeros_like(five_bar.anchors)
    bump[0, 0] = 1.0
    _, tangent = jax.jvp(solved, (anchors,), (jnp.asarray(bump),))
    step = 1e-5
    fd = (solved(anchors + step * bump) - solved(anchors - step * bump)) / (2 * step)
    assert np.max(np.abs(tangent)) > 1e-4
    np.testing.assert_allclose(tangent, fd, rtol=1e-5, atol=1e-7)
