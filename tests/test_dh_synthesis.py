"""DH arms, Yoshikawa manipulability and the eq. 10 synthesis (paper 004).

Properties: the DH map reproduces the paper's printed residuals and ellipsoid volumes;
the equivalent Mechanism's FK, tip Jacobian and manipulability equal the closed form;
w of a planar 2-link arm is l1 l2 |sin q2|; w of the closed-loop five-bar equals |det|
of finite differences of its end effector; the eq. 10 gradient matches finite
differences; a small synthesis reaches its targets and its engine measures match;
bad input gives one-line errors.
"""

import jax.numpy as jnp
import numpy as np
import pytest

import linkopt
from linkopt._arms.dh import synthesis as syn
from linkopt._arms.dh import table as dh
from linkopt._arms.dh.points import read_points
from linkopt._engine.manipulability import manipulability, point_jacobian, yoshikawa

# The paper's DH table (Sec. VI) and its Fig. 3 targets, joint vectors, residuals and
# volumes.
PAPER = dh.table_from_arrays(
    "RRR",
    [1.62611, 1.56317, 1.56376],
    [-1.56998, -0.000493347, 0.0],
    [-0.0403649, -0.00121933, 0.000180823],
)
FIG3 = [
    (
        (1.0, 0.0, 0.0),
        (0.0001335, 4.5756, -2.7249),
        (-0.019091, -0.00063247, 0.0053021),
        0.97052,
    ),
    (
        (0.28366, 0.14112, 0.84147),
        (6.7515, 2.7115, 2.14),
        (0.094132, 0.047255, 0.015007),
        0.86919,
    ),
]
RPR = dh.table_from_arrays(
    "RPR", [0.4, 0.1, 0.5], [np.pi / 2, -np.pi / 2, 0.3], [0.2, 0.4, -0.1]
)  # d1, θ2, d3


def test_link_transform_is_the_distal_product():
    theta, d, a, alpha = 0.7, -0.3, 1.2, -1.1
    rz = np.eye(4)
    rz[:2, :2] = [[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]]
    rx = np.eye(4)
    rx[1:3, 1:3] = [[np.cos(alpha), -np.sin(alpha)], [np.sin(alpha), np.cos(alpha)]]
    tz, tx = np.eye(4), np.eye(4)
    tz[2, 3], tx[0, 3] = d, a
    np.testing.assert_allclose(
        dh.link_transform(theta, d, a, alpha), rz @ tz @ tx @ rx, atol=1e-15
    )


@pytest.mark.parametrize("target, q, residual, volume", FIG3)
def test_paper_figure3_residual_and_volume(target, q, residual, volume):
    """The paper's printed residual (tip − target) and "ellipsoid volume" (= w, eq. 2).

    The joint values are printed to 1e-4 rad; with links of ~1.6 that moves the tip by
    up to ~2e-4, hence the tolerance (a wrong convention is off by 1e-1 or more).
    """
    q = jnp.array(q)
    np.testing.assert_allclose(
        dh.tip_position("RRR", PAPER, q) - np.array(target), residual, atol=2e-4
    )
    w = yoshikawa(dh.tip_jacobian("RRR", PAPER, q))
    assert abs(float(w) - volume) < 1e-4


@pytest.fixture(scope="module")
def rpr_arm():
    q_rest = jnp.array([0.3, 0.25, -0.8])
    mech, _ = dh.to_mechanism("RPR", RPR, q_rest, bounds=(-np.ones(3), np.ones(3)))
    return mech, q_rest


def test_mechanism_fk_matches_closed_form_from_rest(rpr_arm):
    """Engine FK from the rest pose (no closed-form warm start) lands on the DH tip."""
    mech, q_rest = rpr_arm
    offsets = np.random.default_rng(0).uniform(-0.4, 0.4, (6, 3))
    q = q_rest + offsets
    solution = linkopt.solve_fk(mech, offsets)
    assert bool(np.all(solution.converged))
    tip = np.asarray(linkopt.point_positions(mech, solution.state))[:, 0]
    expected = np.stack([dh.tip_position("RPR", RPR, v) for v in q])
    np.testing.assert_allclose(tip, expected, atol=1e-9)
    np.testing.assert_allclose(
        linkopt.motor_values(mech, solution.state), offsets, atol=1e-9
    )


def test_closed_form_state_satisfies_the_engine(rpr_arm):
    """The closed-form state of a far configuration already solves the engine's FK."""
    mech, q_rest = rpr_arm
    q = jnp.array([[2.5, -0.6, 2.9], [-2.0, 0.9, -3.0]])
    start = dh.engine_states("RPR", RPR, q, q_rest, float(mech.length_scale))
    solution = linkopt.solve_fk(mech, dh.motor_values(q, q_rest), start=start)
    assert bool(np.all(solution.converged)) and int(np.max(solution.iterations)) == 0
    jac = point_jacobian(mech, solution.state, "tip", "xyz")
    closed = np.stack([dh.tip_jacobian("RPR", RPR, v) for v in q])
    np.testing.assert_allclose(jac, closed, atol=1e-9)
    w = manipulability(mech, solution.state)
    np.testing.assert_allclose(w, np.abs(np.linalg.det(closed)), rtol=1e-9)


def test_planar_two_link_manipulability_is_l1_l2_sin_q2():
    l1, l2 = 0.7, 0.4
    table = dh.table_from_arrays("RR", [l1, l2], [0.0, 0.0], [0.0, 0.0])
    q_rest = jnp.array([0.3, 1.1])
    mech, _ = dh.to_mechanism("RR", table, q_rest)
    assert [mech.output_names] == [("x", "y")]
    q = jnp.array([[0.3, 1.1], [-1.0, 2.5], [2.0, -0.4], [0.5, -2.9], [0.1, 1e-4]])
    expected = l1 * l2 * np.abs(np.sin(q[:, 1]))
    closed = [float(yoshikawa(dh.tip_jacobian("RR", table, v))) for v in q]
    np.testing.assert_allclose(closed, expected, rtol=1e-12, atol=1e-12)
    start = dh.engine_states("RR", table, q, q_rest, float(mech.length_scale))
    states = linkopt.solve_fk(mech, dh.motor_values(q, q_rest), start=start).state
    np.testing.assert_allclose(
        manipulability(mech, states), expected, rtol=1e-9, atol=1e-12
    )


def test_five_bar_manipulability_matches_finite_differences(five_bar):
    """Closed loop: w from the engine's sensitivities = |det| of FD of the end
    effector."""
    motors = np.array([0.3, -0.2])
    state = linkopt.solve_fk(five_bar, motors).state
    ee = five_bar.point_names.index("ee")

    def xy(a):
        return np.asarray(
            linkopt.point_positions(
                five_bar, linkopt.solve_fk(five_bar, a, start=state).state
            )
        )[ee, :2]

    h = 1e-5
    fd = np.stack(
        [(xy(motors + h * e) - xy(motors - h * e)) / (2 * h) for e in np.eye(2)], axis=1
    )
    np.testing.assert_allclose(
        point_jacobian(five_bar, state), fd, rtol=1e-7, atol=1e-6
    )
    assert float(manipulability(five_bar, state)) == pytest.approx(
        abs(np.linalg.det(fd)), rel=1e-7
    )


def test_eq10_gradient_matches_finite_differences():
    targets = np.array([[0.8, 0.2, 0.3], [0.1, 0.9, -0.2], [-0.5, 0.4, 0.6]])
    x = syn.initial_guess("RPR", targets, np.random.default_rng(3))
    weights = jnp.array([12.0, 25.0, 1e-10, 1e-4])
    _, grad = syn.value_and_grad("RPR", jnp.asarray(x), jnp.asarray(targets), weights)
    h = 1e-6
    fd = [
        (
            syn.cost("RPR", jnp.asarray(x + h * e), targets, weights)
            - syn.cost("RPR", jnp.asarray(x - h * e), targets, weights)
        )
        / (2 * h)
        for e in np.eye(x.size)
    ]
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-5)


TASK = np.array(
    [[np.cos(5 * t), np.sin(3 * t), np.sin(t)] for t in np.arange(0.0, 0.6, 0.1)]
)
SMALL = syn.DHSynthesisSettings(starts=2, seed=1, max_iterations=300)


@pytest.fixture(scope="module")
def small_synthesis():
    return syn.synthesize_config("RRR", TASK, SMALL)


def test_small_synthesis_reaches_its_targets(small_synthesis):
    s = small_synthesis
    assert s.q.shape == (6, 3) and s.residual.max() <= SMALL.reach_tolerance
    assert s.manipulability.min() > 0.1
    assert s.stage1["cost"] == min(s.starts)
    assert s.size == pytest.approx(
        float(np.sum(np.abs(s.table.a)) + np.sum(np.abs(s.table.offset)))
    )


def test_enumeration_keeps_the_best_mean_manipulability():
    assert sorted(syn.all_configurations(3)) == sorted(
        ["PPP", "PPR", "PRP", "RPP", "PRR", "RPR", "RRP", "RRR"]
    )
    best, results = syn.synthesize_dh(
        TASK[:2], 1, syn.DHSynthesisSettings(starts=1, max_iterations=50)
    )
    assert set(results) == {"P", "R"}
    assert np.mean(best.manipulability) == max(
        np.mean(r.manipulability) for r in results.values()
    )


@pytest.mark.parametrize(
    "text, message",
    [
        ("1, 2, 3\n4, 5\n", "line 2: expected 3 finite numbers"),
        ("x, y, z\n1, 2, nan\n", "line 2: expected 3 finite numbers"),
        ("x, y, z\n", "no task points"),
        ("1, 2, 3\n1, two, 3\n", "line 2: expected 3 finite numbers"),
    ],
)
def test_bad_point_files(tmp_path, text, message):
    path = tmp_path / "points.csv"
    path.write_text(text)
    with pytest.raises(linkopt.InputError, match=message) as err:
        read_points(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_bad_input_gives_one_line_errors():
    with pytest.raises(linkopt.InputError, match="joints: expected a number of joints"):
        syn.all_configurations(0)
    with pytest.raises(linkopt.InputError, match="DH table: alpha: expected 3"):
        dh.table_from_arrays("RRR", [1, 1, 1], [0, 0], [0, 0, 0])
    with pytest.raises(linkopt.InputError, match="precision"):
        syn.synthesize_config("RR", TASK[:2], syn.DHSynthesisSettings(precision=-1.0))


def test_enumeration_skips_strings_without_an_engine_model():
    """Regression: ``--joints 4`` failed in engine_report after the whole enumeration
    when the best string had fewer than N - 3 revolute joints."""
    four = syn.configurations(4)
    assert (
        "PPPP" not in four and len(four) == 15 and all(t.count("R") >= 1 for t in four)
    )
    assert syn.configurations(3) == syn.all_configurations(3)
    with pytest.raises(
        linkopt.InputError, match="'PPPPR': a 5-joint arm needs at least 2 revolute"
    ):
        syn.configurations("PPPPR")
    with pytest.raises(
        linkopt.InputError, match="seed: expected a non-negative integer"
    ):
        syn.synthesize_config("RR", TASK[:2], syn.DHSynthesisSettings(seed=-1))


def test_zero_precision_is_refused_before_work():
    with pytest.raises(linkopt.InputError, match="precision: expected a finite"):
        syn.synthesize_config("RR", TASK[:2], syn.DHSynthesisSettings(precision=0.0))
    with pytest.raises(linkopt.InputError, match="starts: 5000 exceeds the limit"):
        syn.synthesize_config("RR", TASK[:2], syn.DHSynthesisSettings(starts=5000))
