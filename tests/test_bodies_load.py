"""The load-time checks of mechanisms of many bodies on the band
(:func:`linkopt._engine.mobility.banded_mobility`, the banded rest program): the same
mobility, σ_min at rest and input-output Jacobian as the dense path, the same errors
for a mechanism of the wrong mobility, and the body-count refusal
(:func:`linkopt._files.topology.check_size`)."""

import dataclasses
import re
import tomllib

import numpy as np
import pytest
from conftest import MECHANISMS
from long_linkages import ladder
from strandbeest import strandbeest
from test_design_roundtrip import AXES
from test_mobility_change import TILTED

from linkopt import MechanismFileError
from linkopt._design.conditioning import rest_conditioning
from linkopt._engine import banded, mobility
from linkopt._engine.geometry import geometry, rest_state
from linkopt._files.fields import parse_toml
from linkopt._files.loader import build, loads
from linkopt._files.topology import DENSE_MAX_BODIES, MAX_BODIES


def _with_factor(mech, factor: str):
    return dataclasses.replace(
        mech, solver=dataclasses.replace(mech.solver, factor=factor)
    )


def _ladder(cells: int, unbraced=(), braced_first: bool = False) -> dict:
    """:func:`long_linkages.ladder` of ``cells`` cells with the braces of the cells
    ``unbraced`` taken out (one more degree of freedom each) or a brace added to the
    first cell (none left)."""
    data = tomllib.loads(ladder(cells))
    gone = {f"x{i}" for i in unbraced}
    data["bodies"] = [b for b in data["bodies"] if b["name"] not in gone]
    data["joints"] = [j for j in data["joints"] if not set(j["bodies"]) & gone]
    if braced_first:
        data["bodies"].append({"name": "x1"})
        for name, body, anchor in (("xl1", "r0", 16.0), ("xr1", "r1", 6.0)):
            x = 0.0 if body == "r0" else 10.0
            data["joints"].append(
                {
                    "name": name,
                    "type": "revolute",
                    "bodies": [body, "x1"] if body == "r0" else ["x1", body],
                    "anchor": [x, anchor, 0.0],
                    "axis": [0.0, 0.0, 1.0],
                }
            )
    return data


def _both(data: dict, name: str):
    mech = build(data, name, check=False)
    return _with_factor(mech, "dense"), _with_factor(mech, "banded")


def _message(mech) -> str | None:
    try:
        mobility.check_mobility(mech)
    except MechanismFileError as err:
        return str(err)
    return None


def test_the_band_counts_the_mobility_and_conditions_the_rest_pose_as_the_dense_path():
    dense, band = _both(_ladder(4), "ladder")
    assert banded.serves(band) and not banded.serves(dense)
    assert mobility.mobility(band) == mobility.mobility(dense) == 1
    assert mobility.rest_jacobians(band).passive is None  # no dense Jacobian formed
    expected, found = rest_conditioning(dense), rest_conditioning(band)
    np.testing.assert_allclose(
        [found.sigma_fk, found.sigma_bk],
        [expected.sigma_fk, expected.sigma_bk],
        rtol=1e-9,
    )
    np.testing.assert_allclose(
        found.jacobian_sigmas, expected.jacobian_sigmas, rtol=1e-9
    )
    assert _message(band) is None


@pytest.mark.parametrize(
    "unbraced, braced_first, dof",
    [((3,), False, 2), ((), True, 0), ((2, 3, 4, 5, 6, 7, 8), False, 8)],
    ids=["one-free-cell", "rigid", "null-space-wider-than-the-block"],
)
def test_a_wrong_mobility_is_refused_on_the_band_with_the_dense_message(
    unbraced, braced_first, dof
):
    """Two motions, none (every cell braced) and eight (wider than the first block
    of six vectors: counted by the second, twice as wide)."""
    dense, band = _both(_ladder(8, unbraced, braced_first), "ladder.toml")
    assert mobility.mobility(band) == mobility.mobility(dense) == dof
    message = _message(band)
    assert message == _message(dense)
    assert message.startswith("ladder.toml: [[motors]]: the mechanism has mobility ")
    assert f"mobility {dof} at the rest pose but 1 motor(s)" in message


def test_small_mechanisms_keep_the_dense_checks():
    mech = loads((MECHANISMS / "five_bar.toml").read_text(), "five_bar.toml")
    assert not banded.serves(mech)
    rest = mobility.rest_jacobians(mech)
    assert rest.passive is not None and rest.rates is None


def test_a_file_of_too_many_bodies_is_refused_in_one_line_naming_file_and_count():
    data = parse_toml(ladder(2), "big.toml")
    data["bodies"] = [{"name": f"b{k}"} for k in range(MAX_BODIES + 1)]
    with pytest.raises(MechanismFileError) as err:
        build(data, "big.toml")
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith("big.toml: [[bodies]]: ")
    assert re.search(rf"\b{MAX_BODIES + 1} bodies\b", text)
    assert f"at most {MAX_BODIES} bodies" in text


def _tangle(bodies: int, seed: int = 0) -> dict:
    """``bodies`` bodies each pinned to three others drawn at random: no order keeps
    the bodies that share a joint near each other (a random graph's band is a good
    part of it wide)."""
    rng = np.random.default_rng(seed)
    joints = []
    for k in range(1, bodies):
        for other in {int(rng.integers(0, k)) for _ in range(3)}:
            joints.append(
                {
                    "name": f"j{len(joints)}",
                    "type": "revolute",
                    "bodies": [f"b{other}", f"b{k}"],
                    "anchor": [float(k), float(other), 0.0],
                    "axis": [0.0, 0.0, 1.0],
                }
            )
    return {
        "mechanism": {"name": "tangle", "ground": "b0", "units": "mm"},
        "bodies": [{"name": f"b{k}"} for k in range(bodies)],
        "joints": joints,
        "motors": [{"name": "m", "joint": "j0"}],
        "outputs": [{"name": "o", "joint": "j1", "min": -0.3, "max": 0.3}],
    }


def test_a_large_file_whose_bodies_fall_into_no_band_is_refused_in_one_line():
    count = DENSE_MAX_BODIES + 10
    with pytest.raises(MechanismFileError) as err:
        build(_tangle(count), "tangle.toml")
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith(f"tangle.toml: [[bodies]]: {count} bodies whose joints ")
    assert f"at most {DENSE_MAX_BODIES} such bodies" in text


def test_the_arrowhead_counts_the_mobility_and_conditions_the_rest_pose_as_dense():
    """A walker of four legs: its ground and crank are hubs of the passive rows too,
    so the mobility test factors an arrowhead."""
    dense, band = _both(tomllib.loads(strandbeest(4)), "walker")
    _, where = banded.passive_normal(band, geometry(band), rest_state(band))
    assert where.hubs == 2
    assert mobility.mobility(band) == mobility.mobility(dense) == 1
    expected, found = rest_conditioning(dense), rest_conditioning(band)
    np.testing.assert_allclose(
        [found.sigma_fk, found.sigma_bk, *found.jacobian_sigmas],
        [expected.sigma_fk, expected.sigma_bk, *expected.jacobian_sigmas],
        rtol=1e-9,
    )


@pytest.mark.parametrize(
    "text, designs",
    [
        (TILTED, lambda p0: [p0, p0 + np.array([0, 0, 0, 0.2])]),
        (AXES, lambda p0: [p0, [0.1, 1.7]]),
    ],
    ids=["four-bar-locks", "spherical-five-bar-couples"],
)
def test_the_band_finds_the_designs_that_change_the_mobility_as_the_dense_path(
    text, designs
):
    """``mobility_changes`` on the band (the optimiser's and ``--design``'s test):
    the same mobility, locked motors and words as the dense SVD for a design that
    locks a four-bar's motor and one that couples a five-bar's two motors."""
    mech = loads(text, "file.toml")
    rows = designs(mech.design.p0)
    expected = mobility.mobility_changes(mech, rows)
    band = _with_factor(mech, "banded")
    found = mobility.mobility_changes(band, rows)
    assert expected[0] is None and found[0] is None
    assert found[1].mobility == expected[1].mobility
    assert found[1].locked == expected[1].locked
    assert found[1].words(band) == expected[1].words(mech)
