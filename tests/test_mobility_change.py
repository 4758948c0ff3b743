"""A design that changes the mobility at rest is named as such (issue 45, part 3).

Tilting one axis of a planar four-bar makes it a general spatial 4R, which cannot move
(mobility 0, 6·3 - 5·4 < 0 and no special geometry); tilting the tip axis of a
spherical five-bar off its centre leaves one motion for two motors. ``--design`` on
``evaluate`` and ``fk``, and ``verify``, refuse such a design with a message naming
the design, the mobility and the motors; the optimiser counts it infeasible and says
why in ``history.csv``."""

import csv
import dataclasses

import numpy as np
import pytest
from conftest import MECHANISMS
from test_design_roundtrip import AXES

import linkopt
from linkopt._cli.main import main
from linkopt._design.optimizer import start, step
from linkopt._design.run import save_checkpoint
from linkopt._design.settings import OptimizerSettings
from linkopt._engine.mobility import mobility_changes

#: The four-bar with its coupler-rocker axis tilted by one parameter.
TILTED = (MECHANISMS / "four_bar.toml").read_text() + (
    '\n[[parameters]]\nname = "tilt"\njoint = "C"\ncoordinate = "axis_x"\n'
    "min = -0.3\nmax = 0.3\n"
)


@pytest.fixture(scope="module")
def tilted():
    return linkopt.loads(TILTED, "tilted.toml")


def test_a_tilted_axis_locks_the_four_bar_and_names_its_motor(tilted):
    p0 = tilted.design.p0
    locked = p0 + np.array([0, 0, 0, 0.2])
    unchanged, change = mobility_changes(tilted, [p0, locked])
    assert unchanged is None
    assert change.mobility == 0 and change.locked == ("crank",)
    words = change.words(tilted)
    assert (
        "the design (ground_d = 60, pin_x = 63.2971, pin_y = 49.8912, tilt = 0.2)"
        in words
    )
    assert (
        "has mobility 0 at the rest pose, the file's 1: motor(s) crank no longer move"
        in words
    )


def test_an_off_centre_tip_couples_the_spherical_five_bars_motors():
    mech = linkopt.loads(AXES, "axes.toml")
    (change,) = mobility_changes(mech, [[0.1, 1.7]])
    assert change.mobility == 1 and change.locked == ()
    assert "motors left, right no longer move independently (only 1" in change.words(
        mech
    )


@pytest.mark.parametrize("command", ["evaluate", "fk"])
def test_design_option_refuses_a_design_that_locks(tmp_path, capsys, command):
    path = tmp_path / "tilted.toml"
    path.write_text(TILTED)
    extra = ["--motors", "0.1"] if command == "fk" else []
    design = "60,63.29705854077836,49.891175622335055,0.2"
    code = main([command, str(path), "--design", design, *extra])
    err = capsys.readouterr().err
    assert code != 0
    assert "--design: the design (ground_d = 60" in err
    assert "has mobility 0 at the rest pose, the file's 1: motor(s) crank" in err


def test_verify_refuses_a_design_that_locks(tilted):
    with pytest.raises(linkopt.InputError, match="mobility 0 at the rest pose"):
        linkopt.verify(tilted, tilted.design.p0 + [0, 0, 0, 0.1], resolution=3)


def test_the_optimiser_counts_a_locking_design_infeasible(tilted, tmp_path):
    settings = OptimizerSettings(particles=4, iterations=1, seed=0, mode="swarm")
    run = start(tilted, settings)
    position = run.position.copy()
    position[0] = tilted.design.p0  # untilted: moves
    position[1:, 3] = [0.05, -0.1, 0.2]
    run = step(tilted, dataclasses.replace(run, position=position), settings)
    record = run.history[-1]
    assert record["refused"] == 3
    assert "tilt = 0.05) has mobility 0" in record["refused_reason"]
    assert np.isfinite(run.pbest_cost[0]) and np.all(np.isinf(run.pbest_cost[1:]))
    np.testing.assert_array_equal(run.result_pos, tilted.design.p0)
    save_checkpoint(tmp_path, run, tilted, settings)
    with open(tmp_path / "history.csv") as f:
        (row,) = list(csv.DictReader(f))
    assert row["refused"] == "3"
    assert row["refused_reason"] == record["refused_reason"]
