"""``--design`` on every command that reads a mechanism (issue 45: the tutorial says
any command takes it, and ``check`` refused it). Each command checks the design
against the parameters' bounds before any work, and a design given as values reads
as the file written at that design does."""

import json

import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._cli.main import main
from linkopt._files.writer import write_design

FIVE = str(MECHANISMS / "five_bar.toml")
DESIGN = "30,40,10"

#: Each command that reads a mechanism, with the arguments it needs besides --design.
COMMANDS = {
    "check": [],
    "fk": ["--motors", "0,0"],
    "bk": ["--outputs", "0,60"],
    "evaluate": [],
    "plot": ["--out", "{tmp}/plots"],
    "verify": [],
    "animate": ["--out", "{tmp}/a.gif"],
    "export": ["--format", "mjcf", "--out", "{tmp}/a.xml"],
    "view": ["--out", "{tmp}/v.html"],
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_takes_design_and_checks_its_bounds(command, tmp_path, capsys):
    extra = [a.format(tmp=tmp_path) for a in COMMANDS[command]]
    argv = [command, FIVE, *extra, "--design", "30,40,500"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--design: elbow_y = 500 is outside its bounds [-20, 80]" in err, err


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The five-bar written at DESIGN, as ``optimize`` writes its result."""
    mech = linkopt.load(FIVE)
    path = tmp_path_factory.mktemp("design") / "at.toml"
    values = [float(v) for v in DESIGN.split(",")]
    return str(write_design(mech, values, 16.0, path))


def _json(argv, capsys) -> dict:
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_check_design_reports_the_file_at_that_design(written, capsys):
    given = _json(["check", FIVE, "--design", DESIGN], capsys)
    from_file = _json(["check", FIVE, "--design", written], capsys)
    plain = _json(["check", FIVE], capsys)
    assert given["design"] == {"base_x": 30.0, "elbow_x": 40.0, "elbow_y": 10.0}
    assert given == from_file
    assert given["joints"]["base_right"]["anchor"] == [30.0, 0.0, 0.0]
    assert given["joints"]["elbow_left"]["anchor"] == [-40.0, 10.0, 0.0]  # mirrored
    assert {k: v["initial"] for k, v in given["parameters"].items()} == given["design"]
    assert given["rest_pose"]["f_sing"] != plain["rest_pose"]["f_sing"]
    # the written file itself, checked plainly, has the same rest pose
    other = _json(["check", written], capsys)
    for key in ("sigma_min_fk", "sigma_min_bk", "f_sing"):
        assert given["rest_pose"][key] == pytest.approx(
            other["rest_pose"][key], rel=1e-9
        )


@pytest.mark.parametrize(
    ("command", "extra"), [("fk", COMMANDS["fk"]), ("bk", COMMANDS["bk"])]
)
def test_fk_and_bk_design_solve_the_file_at_that_design(
    command, extra, written, capsys
):
    given = _json([command, FIVE, *extra, "--design", DESIGN], capsys)
    other = _json([command, written, *extra], capsys)
    assert given["converged"] and other["converged"]
    for group in ("motors", "outputs", "joints"):
        for name, value in given[group].items():
            assert value == pytest.approx(other[group][name], abs=1e-9), (group, name)
