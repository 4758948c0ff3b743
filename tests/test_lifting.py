"""The mechanism as data (``linkopt._engine.lifting``): programs take a mechanism's
numbers as arguments, so two mechanisms of one structure share one traced and compiled
program, and each is computed with its own numbers."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._engine import programs
from linkopt._engine.lifting import padded
from linkopt._engine.structure import structure

MOTORS = np.array([[0.0, 0.0], [0.2, -0.1], [-0.15, 0.25]])


def edited_five_bar() -> linkopt.Mechanism:
    """``five_bar.toml`` with its bases 2 mm further out and its tip 2 mm higher."""
    text = (MECHANISMS / "five_bar.toml").read_text()
    for old, new in (
        ("[-20.0, 0.0, 0.0]", "[-22.0, 0.0, 0.0]"),
        ("[20.0, 0.0, 0.0]", "[22.0, 0.0, 0.0]"),
        ("[0.0, 70.0, 0.0]", "[0.0, 72.0, 0.0]"),
    ):
        assert old in text
        text = text.replace(old, new)
    return linkopt.loads(text, "edited_five_bar.toml")


def test_one_structure_one_program_each_its_own_numbers(five_bar, monkeypatch):
    edited = edited_five_bar()
    assert structure(padded(edited)) == structure(padded(five_bar))
    monkeypatch.setattr(programs, "PROGRAMS", {})
    traced = []
    real_export = programs.export.export

    def recording(fn, *args, **kwargs):
        traced.append(fn)
        return real_export(fn, *args, **kwargs)

    monkeypatch.setattr(programs.export, "export", recording)
    ours = linkopt.solve_fk(five_bar, MOTORS)
    theirs = linkopt.solve_fk(edited, MOTORS)
    assert len(traced) <= 1  # none when an earlier run left the trace on disk
    assert [name for name, *_ in programs.PROGRAMS].count("from_rest_fk") == 1
    # the edited file's numbers, not the first file's: against a trace that bakes
    # the edited file's numbers in as constants
    baked = jax.jit(lambda m: linkopt.solve_fk(edited, m).state)(MOTORS)
    np.testing.assert_allclose(theirs.state, baked, rtol=0, atol=1e-12)
    assert np.max(np.abs(np.asarray(theirs.state) - np.asarray(ours.state))) > 1e-3
    tips = np.asarray(linkopt.point_positions(edited, theirs.state))[:, 0, :2]
    anchors = np.asarray(linkopt.joint_positions(edited, theirs.state))
    np.testing.assert_allclose(tips, anchors[:, 4, :2], rtol=0, atol=1e-9)


def test_a_second_file_of_the_same_linkage_shares_the_delta_programs():
    delta = linkopt.load(MECHANISMS / "delta.toml")
    deep = linkopt.load(MECHANISMS / "delta_deep_box.toml")
    assert structure(padded(delta)) == structure(padded(deep))
    assert not np.array_equal(delta.output_min, deep.output_min)


@pytest.mark.parametrize(
    "other",
    [
        lambda m: linkopt.load(MECHANISMS / "four_bar.toml"),
        lambda m: dataclasses.replace(
            m, joint_types=("revolute",) * 4 + ("spherical",)
        ),
        lambda m: dataclasses.replace(
            m, evaluation=dataclasses.replace(m.evaluation, samples_per_dimension=4)
        ),
        lambda m: dataclasses.replace(
            m, evaluation=dataclasses.replace(m.evaluation, targets=((0.0, 60.0),))
        ),
    ],
    ids=["another linkage", "another joint family", "another grid", "more targets"],
)
def test_what_shapes_a_program_is_in_the_key(five_bar, other):
    assert structure(padded(other(five_bar))) != structure(padded(five_bar))


def test_numbers_and_names_are_not_in_the_key(five_bar):
    renamed = dataclasses.replace(five_bar, name="other", source="x.toml", raw={})
    assert structure(padded(renamed)) == structure(padded(five_bar))
    assert structure(padded(retuned_five_bar(five_bar))) == structure(padded(five_bar))
    moved = jax.tree_util.tree_map(lambda v: v + 1, five_bar)
    assert structure(padded(moved)) == structure(padded(five_bar))


def test_a_number_used_as_a_constant_fails_loudly(five_bar):
    """A program that turned a traced number into numpy would bake the first
    mechanism's value into a program that others reuse; it cannot be traced."""

    def baking(m, x):
        return x + float(np.sum(np.asarray(m.anchors)))

    with pytest.raises(jax.errors.TracerArrayConversionError):
        programs.call("baking", five_bar, baking, jnp.ones(2))


def retuned_five_bar(five_bar) -> linkopt.Mechanism:
    """``five_bar`` with other names and other ``[solver]``/``[evaluation]`` numbers:
    short iteration caps, other weights and step, an α₋, one extra target moved."""
    renamed = {
        name: tuple(f"{n}_x" for n in getattr(five_bar, name))
        for name in ("body_names", "joint_names", "point_names", "motor_names")
    }
    solver = dataclasses.replace(five_bar.solver, max_iterations=7, tolerance=1e-9)
    evaluation = dataclasses.replace(
        five_bar.evaluation,
        ik_iterations=3,
        adversarial_iterations=2,
        motion_weight=0.5,
        range_weight=2.0,
        regularizer_weight=0.1,
        max_step=0.05,
        alpha_minus=30.0,
    )
    design = dataclasses.replace(
        five_bar.design, names=tuple(f"{n}_x" for n in five_bar.design.names)
    )
    return dataclasses.replace(
        five_bar,
        **renamed,
        solver=solver,
        evaluation=evaluation,
        design=design,
        output_names=("u", "v"),
    )


def test_settings_are_data_each_file_computed_with_its_own(five_bar, monkeypatch):
    """A file with other settings and names shares the five-bar's evaluation
    program and is evaluated with its own settings: equal to a program that bakes
    them in as constants, and unlike the five-bar's own evaluation."""
    from linkopt._design.evaluation import evaluate_homogenised

    retuned = retuned_five_bar(five_bar)
    monkeypatch.setattr(programs, "PROGRAMS", {})
    design = np.asarray(five_bar.design.p0)[None]
    ours = linkopt.evaluate(five_bar, design)
    theirs = linkopt.evaluate(retuned, design)
    assert [name for name, *_ in programs.PROGRAMS].count("evaluate") == 1
    baked = jax.jit(lambda d: evaluate_homogenised(retuned, d, 30.0))(design)
    for field in ("f_design", "ik_f_sing", "adv_f_sing", "ik_iterations"):
        np.testing.assert_allclose(
            getattr(theirs, field), getattr(baked, field), rtol=1e-10, atol=1e-12
        )
    assert int(np.max(theirs.ik_iterations)) <= 3
    assert int(np.max(ours.ik_iterations)) > 3


def five_bar_without_elbow_y() -> linkopt.Mechanism:
    """``five_bar.toml`` with two design parameters instead of three."""
    text = (MECHANISMS / "five_bar.toml").read_text()
    table = text[text.index('[[parameters]]\nname = "elbow_y"') :]
    table = table[: table.index("\n\n") + 2]
    return linkopt.loads(text.replace(table, ""), "five_bar_2p.toml")


def test_a_file_with_fewer_parameters_shares_the_programs(five_bar, monkeypatch):
    """Designs enter programs padded to their class (3 and 2 parameters: 4), so a
    file that loses a parameter reuses the evaluation and the partial gradient, and
    each result is its own: equal to a program made for it alone."""
    from linkopt._design.evaluation import alpha_minus, evaluate_homogenised
    from linkopt._design.partial import gradients_homogenised

    fewer = five_bar_without_elbow_y()
    assert fewer.design.size == 2 and five_bar.design.size == 3
    assert structure(padded(fewer)) == structure(padded(five_bar))
    monkeypatch.setattr(programs, "PROGRAMS", {})
    linkopt.evaluate(five_bar)
    design = np.asarray(fewer.design.p0) + np.array([3.0, -4.0])
    theirs = linkopt.evaluate(fewer, design)
    gradient = linkopt.partial_gradient(fewer, design, theirs, alpha_minus(fewer))
    assert [name for name, *_ in programs.PROGRAMS].count("evaluate") == 1
    assert np.shape(gradient) == (2,)
    alpha = alpha_minus(fewer)
    baked = jax.jit(lambda d: evaluate_homogenised(fewer, d, alpha))(design)
    np.testing.assert_allclose(theirs.f_design, baked.f_design, rtol=1e-10)
    np.testing.assert_allclose(theirs.ik_states, baked.ik_states, atol=1e-10)
    grad = jax.jit(lambda d, e: gradients_homogenised(fewer, d, e, alpha))
    np.testing.assert_allclose(gradient, grad(design, baked), rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize(("size", "padded"), [(0, 4), (1, 4), (4, 4), (5, 8), (12, 16)])
def test_design_classes(size, padded):
    from linkopt._engine.lifting import design_class

    assert design_class(size) == padded


def test_padded_designs_inside_a_users_trace(five_bar):
    """A design that is a tracer (the partial gradient inside ``jax.jit``) is padded
    by ``jax.numpy`` and gives the concrete call's gradient."""
    from linkopt._design.evaluation import alpha_minus

    ev = linkopt.evaluate(five_bar)
    alpha = alpha_minus(five_bar)
    p0 = np.asarray(five_bar.design.p0)
    concrete = linkopt.partial_gradient(five_bar, p0, ev, alpha)
    traced = jax.jit(lambda d: linkopt.partial_gradient(five_bar, d, ev, alpha))(p0)
    assert traced.shape == (five_bar.design.size,)
    np.testing.assert_allclose(traced, concrete, rtol=1e-9, atol=1e-12)
