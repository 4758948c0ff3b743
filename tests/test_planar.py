"""One planarity test for every figure (issue 44): a prismatic axis in the plane keeps
a mechanism planar, so ``animate`` draws the shipped linear slider-crank flat as
``plot`` does; a prismatic axis out of the plane, or a revolute axis not along the
normal, makes it spatial for both."""

import dataclasses

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._draw.animation import plane_basis
from linkopt._draw.planar import plane_normal
from linkopt._draw.plots import mechanism_views

SLIDER = (MECHANISMS / "slider_crank_linear.toml").read_text()


@pytest.mark.parametrize("name", ["slider_crank_linear", "slider_crank"])
def test_a_slider_in_the_plane_is_planar_for_plot_and_animate(name):
    mech = linkopt.load(MECHANISMS / f"{name}.toml")
    np.testing.assert_allclose(np.abs(plane_normal(mech)), [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(plane_basis(mech), np.eye(3)[:2])
    assert mechanism_views(mech) == [(0, 1)]


@pytest.mark.parametrize(
    ("joint", "axis"),
    [("slide", [0.6, 0.0, 0.8]), ("O", [0.0, 0.6, 0.8])],
    ids=["slide out of the plane", "pivot off the normal"],
)
def test_an_axis_out_of_place_makes_it_spatial_for_both(joint, axis):
    """(Geometry only: such a drawing would not move, so it is edited after
    loading.)"""
    mech = linkopt.load(MECHANISMS / "slider_crank_linear.toml")
    axes = np.array(mech.axes, dtype=float)
    axes[mech.joint_names.index(joint)] = axis
    mech = dataclasses.replace(mech, axes=axes)
    assert plane_normal(mech) is None and plane_basis(mech) is None
    assert mechanism_views(mech) == [(0, 1), (0, 2), (1, 2)]


def test_the_plane_need_not_be_a_coordinate_plane():
    """The whole slider-crank rotated about x by 30°: still planar, normal rotated."""
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    rotation = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    mech = linkopt.load(MECHANISMS / "slider_crank_linear.toml")
    turned = linkopt.loads(_rotated(SLIDER, rotation))
    np.testing.assert_allclose(
        np.abs(plane_normal(turned)), np.abs(rotation @ plane_normal(mech)), atol=1e-12
    )


def _rotated(text: str, rotation: np.ndarray) -> str:
    """``text`` with every ``anchor``/``axis`` vector rotated."""
    import re

    def turn(match):
        v = rotation @ np.array([float(x) for x in match.group(2).split(",")])
        return f"{match.group(1)} = [{', '.join(repr(float(x)) for x in v)}]"

    return re.sub(r"^(anchor|axis) = \[([^\]]*)\]", turn, text, flags=re.M)
