"""Design evaluation on the five-bar against its closed-form workspace and
singularities."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS
from five_bar_closed_form import (
    B_L,
    B_R,
    L1,
    L2,
    cross,
    elbows,
    forward_singular_height,
    inverse,
)

import linkopt
from linkopt._design.evaluation import alpha_minus, evaluate, targets
from linkopt._design.metrics import thresholds
from linkopt._design.objectives import adversarial_objective, either, ik_objective
from linkopt._design.sampling import evaluate_point, minimise, minimise_queue
from linkopt._engine.constraints import homogenised_output_values
from linkopt._engine.geometry import rest_state


def reachable_on_rest_branch(tips):
    """Closed form: both dyads reach the tip, and the tip is in the rest working
    mode."""
    tips = np.atleast_2d(tips)
    within = (np.linalg.norm(tips - B_L, axis=1) <= L1 + L2) & (
        np.linalg.norm(tips - B_R, axis=1) <= L1 + L2
    )
    with np.errstate(invalid="ignore"):
        e_l, e_r = elbows(inverse(tips))
    return within & (cross(e_r - e_l, tips - e_l) > 0)


def test_closed_form_confirms_the_initial_defects(five_bar):
    xs = np.linspace(five_bar.output_min[0], five_bar.output_max[0], 81)
    ys = np.linspace(five_bar.output_min[1], five_bar.output_max[1], 66)
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    ok = reachable_on_rest_branch(grid)
    assert 0.5 < ok.mean() < 0.95  # part of the box is out of reach on the rest branch
    assert five_bar.output_min[1] < forward_singular_height() < five_bar.output_max[1]


def test_ik_samples_reach_exactly_the_closed_form_reachable_targets(
    five_bar, five_bar_evaluation
):
    ev = five_bar_evaluation
    expected = reachable_on_rest_branch(targets(five_bar))
    reach = np.asarray(ev.ik_reach)
    assert np.all(reach[expected] < 1e-12)
    assert np.all(reach[~expected] > 1e-4)
    assert float(ev.reach) > 1e-4


def test_adversarial_samples_find_the_forward_singularity(
    five_bar, five_bar_evaluation
):
    ev = five_bar_evaluation
    assert np.any(np.asarray(ev.adv_culled) > 0)
    assert float(ev.singularity) > 0 and float(ev.f_design) == pytest.approx(
        float(ev.reach + ev.singularity)
    )
    # every sample keeps its loop closed
    for states in (ev.ik_states, ev.adv_states):
        motors = linkopt.motor_values(five_bar, states)
        assert np.all(
            np.asarray(linkopt.solve_fk(five_bar, motors, start=states).iterations) <= 1
        )


def _near_forward_singularity(five_bar, th):
    """A solved five-bar pose on the symmetric motor diagonal (towards the forward
    singularity near a = ±0.43) where α₋ < f_sing < α₊: the singularity terms are
    active and not flat."""
    diagonal = np.linspace(0.40, 0.425, 51)
    path = linkopt.solve_fk_path(five_bar, np.stack([diagonal, -diagonal], 1))
    f_path = np.asarray(linkopt.f_sing(five_bar, path.state))
    k = int(np.flatnonzero((f_path > float(th.lower)) & (f_path < float(th.upper)))[0])
    return jnp.array([diagonal[k], -diagonal[k]]), path.state[k]


@pytest.mark.parametrize("kind", ["ik", "adversarial"])
def test_objective_gradients_match_finite_differences(five_bar, kind):
    geom = linkopt.geometry(five_bar)
    th = thresholds(alpha_minus(five_bar))
    motors, state = _near_forward_singularity(five_bar, th)
    if kind == "ik":
        objective = ik_objective(
            five_bar,
            geom,
            jnp.asarray(np.array([0.0, 15.0]) / five_bar.length_scale),
            th,
        )
    else:  # the box's lower edge brought to the pose, so that the range barrier counts
        outputs = homogenised_output_values(five_bar, geom, state)  # homogenised
        low = outputs - jnp.array([0.5, 0.01])
        objective = adversarial_objective(
            five_bar, geom, motors + 0.05, low, low + 2.0, th
        )
    # one jitted program for the point and the differences' points (numpy arguments
    # each time, so one trace): op by op, its vjp, jacfwd and solve compiled over a
    # hundred small programs
    jitted = jax.jit(lambda a, s: evaluate_point(objective, five_bar, geom, a, s)[:2])

    def point(a, s):
        return jitted(np.asarray(a), np.asarray(s))

    _, gradient = point(motors, state)

    def value_at(a):
        s = linkopt.solve_fk(five_bar, a, start=state).state
        return float(point(a, s)[0])

    h = 1e-6
    fd = [
        (value_at(motors + h * e) - value_at(motors - h * e)) / (2 * h)
        for e in np.eye(2)
    ]
    np.testing.assert_allclose(gradient, fd, rtol=1e-5)


def _two_designs_lanes(five_bar):
    """The lanes of the initial design and one 2 % larger: geometries, targets, zero
    motors and the rest state, one row per (design, target)."""
    goals = jnp.asarray(targets(five_bar) / five_bar.output_scale)
    geoms = [
        linkopt.geometry(five_bar),
        linkopt.geometry(five_bar, five_bar.design.p0 * 1.02),
    ]
    lane_geoms = jax.tree_util.tree_map(
        lambda *g: jnp.repeat(jnp.stack(g), len(goals), axis=0), *geoms
    )
    lane_goals = jnp.tile(goals, (2, 1))
    lanes = len(lane_goals)
    zero = jnp.zeros((lanes, five_bar.num_motors))
    rest = jnp.broadcast_to(rest_state(five_bar), (lanes,) + rest_state(five_bar).shape)
    return lane_geoms, lane_goals, zero, rest


def _vmapped_phases(five_bar, th, low, high, caps, lane_geoms, lane_goals, zero, rest):
    """Each phase of every lane by ``vmap(minimise)``, the reference of the queue."""

    def ik(geom, goal, motors, state):
        return minimise(
            five_bar,
            geom,
            ik_objective(five_bar, geom, goal, th),
            motors,
            state,
            caps[0],
            bfgs=False,
        )

    def adversarial(geom, motors, state):
        return minimise(
            five_bar,
            geom,
            adversarial_objective(five_bar, geom, motors, low, high, th),
            motors,
            state,
            caps[1],
            bfgs=True,
        )

    expected_ik = jax.jit(jax.vmap(ik))(lane_geoms, lane_goals, zero, rest)
    expected_adv = jax.jit(jax.vmap(adversarial))(
        lane_geoms, expected_ik.motors, expected_ik.state
    )
    return expected_ik, expected_adv


def test_queued_lanes_take_the_same_steps_as_vmapped_lanes(five_bar):
    """IK then adversarial minimisation of the lanes of two designs through 5 slots end
    where ``vmap(minimise)`` of each phase ends them, after as many iterations (IK
    counts spread from a few to the cap)."""
    th = thresholds(alpha_minus(five_bar))
    low = jnp.asarray(five_bar.output_min / five_bar.output_scale)
    high = jnp.asarray(five_bar.output_max / five_bar.output_scale)
    lane_geoms, lane_goals, zero, rest = _two_designs_lanes(five_bar)
    caps = (
        five_bar.evaluation.ik_iterations,
        five_bar.evaluation.adversarial_iterations,
    )

    def problem(lane, second, anchor):
        geom, goal = lane
        return geom, either(
            ik_objective(five_bar, geom, goal, th),
            adversarial_objective(five_bar, geom, anchor, low, high, th),
            second,
        )

    expected_ik, expected_adv = _vmapped_phases(
        five_bar, th, low, high, caps, lane_geoms, lane_goals, zero, rest
    )
    queued = jax.jit(
        lambda *a: minimise_queue(five_bar, problem, (a[0], a[1]), a[2], a[3], caps, 5)
    )(lane_geoms, lane_goals, zero, rest)
    iterations = np.asarray(expected_ik.iterations)
    assert (
        iterations.min() < 15 and iterations.max() == caps[0]
    )  # a spread worth queueing
    for got, expected in zip(queued, (expected_ik, expected_adv)):
        np.testing.assert_array_equal(
            np.asarray(got.iterations), np.asarray(expected.iterations)
        )
        np.testing.assert_allclose(got.motors, expected.motors, rtol=0, atol=1e-8)
        np.testing.assert_allclose(got.value, expected.value, rtol=1e-8, atol=1e-14)
        np.testing.assert_allclose(got.f_sing, expected.f_sing, rtol=1e-8)


def test_a_design_far_from_singularities_scores_zero():
    text = (MECHANISMS / "five_bar.toml").read_text()
    text = text.replace("min = -40.0\nmax = 40.0", "min = -10.0\nmax = 10.0").replace(
        "min = 15.0\nmax = 80.0", "min = 58.0\nmax = 72.0"
    )
    mech = linkopt.loads(text, "small_box.toml")
    tips = np.stack(
        np.meshgrid(np.linspace(-10, 10, 21), np.linspace(58, 72, 15)), -1
    ).reshape(-1, 2)
    solved = linkopt.solve_bk(mech, tips)
    assert np.all(solved.converged)
    assert float(np.max(linkopt.f_sing(mech, solved.state))) < 0.6 * alpha_minus(
        mech
    )  # far from α₋
    ev = evaluate(mech)
    assert float(ev.f_design) < 1e-6
    assert float(np.max(ev.adv_culled)) == 0.0


@pytest.mark.parametrize(
    "design, field",
    [
        ([1.0], "design"),
        ([[1.0, 2.0]], "design[0]"),
        ([[20.0, 40.0, float("nan")]], "design[0]"),
        ("abc", "design"),
        ([[[1.0, 2.0, 3.0]]], "design"),
    ],
)
def test_a_malformed_design_is_refused_naming_it(five_bar, design, field):
    from linkopt import InputError

    with pytest.raises(InputError, match=rf"^{re.escape(field)}: expected"):
        evaluate(five_bar, design)


def test_an_adversarial_sample_never_ends_below_its_start():
    """Regression: on the delta's deep box, 6 of 27 adversarial samples ended at a lower
    f_sing than the IK sample they started from (the range barrier pulled them inward
    from the box's boundary), so f_design read low. A sample whose start lies in the
    range is now never below that start."""
    mech = linkopt.load(MECHANISMS / "delta_deep_box.toml")
    ev = linkopt.evaluate(mech)
    outputs = np.asarray(linkopt.output_values(mech, ev.ik_states))
    slack = 1e-9 * np.asarray(mech.output_scale)
    low, high = mech.output_min - slack, mech.output_max + slack
    inside = np.all((outputs >= low) & (outputs <= high), axis=1)
    assert inside.sum() >= 6
    ik, adv = np.asarray(ev.ik_f_sing), np.asarray(ev.adv_f_sing)
    assert np.all(adv[inside] >= ik[inside])
    # the sample is a configuration: its state has the f_sing it reports
    np.testing.assert_allclose(
        np.asarray(linkopt.f_sing(mech, ev.adv_states)), adv, rtol=1e-9
    )
