"""Four-bar closed forms (linkopt._synth.fourbar) against independent checks:
circle intersections, brute force over the crank angle, textbook Grashof classes."""

import numpy as np
import pytest
from synth_fourbars import circle_intersection, coupler_curve

import linkopt
from linkopt._synth.fourbar import (
    FourBar,
    PathFit,
    PlacedFourBar,
    fit_path,
    four_bar_design,
    freudenstein,
    full_turn_crank,
    grashof_class,
    link_ratio,
    precision_path,
    read_four_bar,
    transmission,
)

# (crank, coupler, rocker, ground) -> Grashof class (Norton, Design of Machinery 2.12)
CLASSES = [
    ((20, 70, 50, 60), "crank-rocker"),  # mechanisms/four_bar.toml
    ((2, 7, 9, 6), "crank-rocker"),
    ((60, 70, 50, 20), "double-crank"),  # drag link: the ground is shortest
    ((60, 70, 20, 50), "rocker-crank"),
    ((50, 20, 60, 70), "double-rocker"),  # Grashof: the coupler is shortest
    ((2, 5, 2, 5), "change-point"),  # parallelogram
    ((3, 4, 5, 6), "change-point"),  # 3 + 6 = 4 + 5
    ((40, 60, 50, 45), "triple-rocker"),
]


@pytest.mark.parametrize("lengths, kind", CLASSES)
def test_grashof_class_of_textbook_four_bars(lengths, kind):
    four_bar = FourBar(*map(float, lengths))
    assert grashof_class(four_bar) == kind
    turns = kind in ("crank-rocker", "double-crank") or (
        kind == "change-point" and lengths[0] == min(lengths)
    )
    assert full_turn_crank(four_bar) == turns


def test_link_ratio_is_longest_over_shortest():
    assert link_ratio(FourBar(20.0, 70.0, 50.0, 60.0)) == pytest.approx(3.5)


def _brute_transmission(a, b, c, d, count=10_000):
    """mu at C between C->B and C->D, over ``count`` crank angles where it
    assembles (both branches give the same mu)."""
    phi = np.linspace(0, 2 * np.pi, count, endpoint=False)
    pin = a * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    ground = np.broadcast_to([d, 0.0], pin.shape)
    rocker = circle_intersection(pin, ground, b, c, 1)
    u, v = pin - rocker, ground - rocker
    cos = np.sum(u * v, axis=1) / (
        np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1)
    )
    mu = np.arccos(np.clip(cos, -1, 1))
    return np.nanmin(mu), np.nanmax(mu)


@pytest.mark.parametrize("lengths", [(20, 70, 50, 60), (60, 70, 50, 20), (2, 7, 9, 6)])
def test_transmission_angle_matches_brute_force_over_the_turn(lengths):
    closed = transmission(FourBar(*map(float, lengths)))
    least, greatest = _brute_transmission(*lengths)
    # phi = 0 and pi are on the grid: exact to round-off
    assert closed.least == pytest.approx(least, abs=1e-9)
    assert closed.greatest == pytest.approx(greatest, abs=1e-9)
    assert closed.worst == pytest.approx(min(least, np.pi - greatest), abs=1e-9)


def test_transmission_angle_of_a_rocker_reaches_its_toggle():
    """Non-Grashof: the crank stops where mu is 0 (or pi); the grid comes within
    the square root of its step of it."""
    closed = transmission(FourBar(40.0, 60.0, 50.0, 45.0))
    least, greatest = _brute_transmission(40, 60, 50, 45)
    assert closed.least == 0.0 and least < 0.05
    assert closed.greatest == pytest.approx(greatest, abs=1e-9)


def _three_pairs():
    """log10 over [1, 2] on a 60-degree crank and 90-degree rocker span
    (Chebyshev spacing): the classic textbook function generator."""
    x = 1.5 + 0.5 * np.cos(np.array([5, 3, 1]) * np.pi / 6)
    phi = np.radians(45.0) + np.radians(60.0) * (x - 1)
    psi = np.radians(135.0) + np.radians(90.0) * np.log10(x) / np.log10(2)
    return phi, psi


def test_freudenstein_closes_the_loop_at_the_three_pairs():
    phi, psi = _three_pairs()
    fit = freudenstein(phi, psi, ground=10.0)
    k1, k2, k3 = fit.k
    np.testing.assert_allclose(
        k1 * np.cos(psi) - k2 * np.cos(phi) + k3, np.cos(phi - psi), atol=1e-10
    )
    a, b, c, d = fit.crank, fit.coupler, fit.rocker, fit.ground
    pin = a * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    rocker = np.array([d, 0.0]) + c * np.stack([np.cos(psi), np.sin(psi)], axis=1)
    np.testing.assert_allclose(np.linalg.norm(rocker - pin, axis=1), b, atol=1e-10)
    assert k1 == pytest.approx(d / a) and k2 == pytest.approx(d / c)
    assert k3 == pytest.approx((a * a - b * b + c * c + d * d) / (2 * a * c))


def test_freudenstein_recovers_a_known_four_bar():
    a, b, c, d = 20.0, 70.0, 50.0, 60.0
    phi = np.array([0.4, 1.5, 2.9])
    pin = a * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    rocker = circle_intersection(pin, np.broadcast_to([d, 0.0], pin.shape), b, c, 1)
    psi = np.arctan2(rocker[:, 1], rocker[:, 0] - d)
    fit = freudenstein(phi, psi, ground=d)
    np.testing.assert_allclose([fit.crank, fit.coupler, fit.rocker], [a, b, c])


def test_freudenstein_refuses_pairs_without_a_coupler():
    with pytest.raises(linkopt.InputError, match="phi, psi"):
        freudenstein([0.1, 0.1, 0.1], [1.0, 1.0, 1.0])


def _on_coupler_curve(placed: PlacedFourBar, points, crank_turns):
    """Largest distance of ``points`` from the placed linkage's coupler point at
    crank angles ``phi_1 + turn`` (closed form, in the ground frame), the nearer of
    the two assembly branches."""
    fb = placed.four_bar()
    g = np.arctan2(*(placed.D - placed.A)[::-1])
    turn = np.array([[np.cos(g), np.sin(g)], [-np.sin(g), np.cos(g)]])
    local = (np.asarray(points) - placed.A) @ turn.T
    phi = placed.crank_angle + np.r_[0.0, crank_turns]
    args = (fb.crank, fb.coupler, fb.rocker, fb.ground, *fb.point, phi)
    gaps = [np.linalg.norm(coupler_curve(*args, s) - local, axis=1) for s in (1, -1)]
    return np.max(np.minimum(*gaps))


def test_three_precision_points_lie_on_the_coupler_curve():
    points = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 1.0]])
    crank = np.array([0.9, 1.8])
    placed = precision_path(points, [0.3, 0.5], crank, [0.4, 0.7])
    np.testing.assert_allclose(placed.P, points[0])
    assert _on_coupler_curve(placed, points, crank) < 1e-9


@pytest.mark.parametrize("count", [3, 4, 5])
def test_fit_path_points_lie_on_the_coupler_curve(count):
    """pylinkage's README example (four points), one fewer and one more; a fit
    with zero residual meets each point at its crank turn (closed form)."""
    points = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 1.0], [3.0, 0.0], [1.5, -0.8]])
    fit = fit_path(points[:count], seed=3)
    assert np.linalg.norm(fit.placed.P - points[0]) < 1e-12
    if count < 5:  # 3 points: exact for any turns; 4: a one-parameter family
        assert fit.residual < 1e-10
    if fit.residual < 1e-10:
        assert _on_coupler_curve(fit.placed, points[:count], fit.crank_turns) < 1e-9


def test_fit_path_refuses_too_many_points():
    with pytest.raises(linkopt.InputError, match="points: expected"):
        fit_path(np.zeros((6, 2)), seed=0)


def test_read_four_bar_of_the_shipped_file_and_its_design_round_trip():
    mech = linkopt.load("mechanisms/four_bar.toml")
    placed = read_four_bar(mech)
    fb = placed.four_bar()
    np.testing.assert_allclose(fb.lengths, [20.0, 70.0, 50.0, 60.0], atol=1e-9)
    np.testing.assert_allclose(placed.world(placed.P), [35.0, 55.0, 0.0], atol=1e-12)
    design = np.array([65.0, 60.0, 52.0])
    moved = read_four_bar(mech, design)
    assert np.linalg.norm(moved.D - moved.A) == pytest.approx(65.0)
    np.testing.assert_allclose(four_bar_design(mech, moved), design, atol=1e-9)
    # the crank pin B is no design parameter: a longer crank cannot be written
    longer = PlacedFourBar(moved.A, moved.B * 1.5, moved.C, moved.D, moved.P)
    assert four_bar_design(mech, longer) is None


def _known_positions(phis, branches):
    """Poses of the crank-rocker (20, 70, 50, 60), coupler point (15, 10), at crank
    angles ``phis`` on the given branches: the points and the coupler, crank and
    rocker turns from the first pose."""
    a, b, c, d, u, v = 20.0, 70.0, 50.0, 60.0, 15.0, 10.0
    phis = np.asarray(phis, dtype=float)
    pins = a * np.stack([np.cos(phis), np.sin(phis)], axis=1)
    ground = np.broadcast_to([d, 0.0], pins.shape)
    rockers = np.vstack(
        [circle_intersection(p, [d, 0.0], b, c, s)[0] for p, s in zip(pins, branches)]
    )
    points = np.vstack(
        [coupler_curve(a, b, c, d, u, v, [f], s)[0] for f, s in zip(phis, branches)]
    )
    coupler = np.unwrap(np.arctan2(*(rockers - pins).T[::-1]))
    rocker = np.unwrap(np.arctan2(*(rockers - ground).T[::-1]))
    turns = [coupler[1:] - coupler[0], phis[1:] - phis[0], rocker[1:] - rocker[0]]
    return points, turns, pins[0], rockers[0]


def test_precision_path_recovers_a_known_four_bar_and_its_circuit():
    points, turns, pin, rocker = _known_positions([0.3, 1.4, 2.6], [1, 1, 1])
    placed = precision_path(points, *turns)
    for got, want in zip(
        (placed.A, placed.B, placed.C, placed.D), ([0, 0], pin, rocker, [60, 0])
    ):
        np.testing.assert_allclose(got, want, atol=1e-9)
    assert PathFit(placed, *turns, 0.0).one_circuit()
    # the third point taken on the other assembly: the classic branch defect
    points, turns, _, _ = _known_positions([0.3, 1.4, 2.6], [1, 1, -1])
    placed = precision_path(points, *turns)
    np.testing.assert_allclose(placed.four_bar().lengths, [20, 70, 50, 60], atol=1e-9)
    assert not PathFit(placed, *turns, 0.0).one_circuit()


@pytest.mark.parametrize(
    "crank, closed, expected",
    [
        ([0.5, 1.0], False, True),
        ([1.0, 0.5], False, False),
        ([3.0, 6.5], False, False),  # more than one turn
        ([-0.5, -1.0], False, True),
        ([2.0, 4.0], True, True),
        ([4.0, 2.0], True, False),
        ([-1.0, -2.0], True, True),
    ],
)
def test_path_fit_order_follows_the_crank_turns(crank, closed, expected):
    placed = PlacedFourBar(*np.zeros((5, 2)))
    fit = PathFit(placed, np.zeros(2), np.array(crank), np.zeros(2), 0.0)
    assert fit.in_order(closed) == expected


def test_read_four_bar_refuses_another_linkage():
    with pytest.raises(linkopt.InputError, match="not a planar four-bar"):
        read_four_bar(linkopt.load("mechanisms/five_bar.toml"))
