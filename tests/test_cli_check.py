"""``linkopt check FILE``: a summary of a mechanism file (text or ``--json``); a broken
or missing file exits 2 with one ``linkopt: error:`` line."""

import json

import pytest
from conftest import MECHANISMS
from test_mechanism_files import BROKEN

from linkopt._cli.main import main


@pytest.mark.parametrize("name", sorted(BROKEN))
def test_check_reports_a_broken_file_in_one_line(name, tmp_path, capsys):
    text, _, message = BROKEN[name]
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err and err.startswith("linkopt: error:")


def test_missing_file_is_a_clear_error(tmp_path, capsys):
    assert main(["check", str(tmp_path / "nope.toml")]) == 2
    assert "nope.toml: file not found" in capsys.readouterr().err


def test_check_json_reports_required_keys(capsys):
    assert main(["check", str(MECHANISMS / "five_bar.toml"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (
        info["state_size"] == 35
        and info["mobility"] == 2
        and info["design_parameters"] == 3
    )
    assert info["constraint_rows"]["fk"] == 38 and info[
        "reference_length"
    ] == pytest.approx(74.0)
    assert set(info["motors"]) == {"left", "right"} and set(info["outputs"]) == {
        "x",
        "y",
    }
    assert info["joints"]["tip"]["anchor"] == [0.0, 70.0, 0.0]


def _one_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err
    return err


@pytest.mark.parametrize(
    "edit, words",
    [
        (
            lambda text: text.replace('type = "revolute"', 'type = ["revolute"]', 1),
            "joints[0].type: expected a joint type string",
        ),
        (
            lambda text: text + "deep = " + "[" * 5000 + "]" * 5000 + "\n",
            "invalid TOML: arrays or tables nested too deeply",
        ),
    ],
    ids=["a list for a joint type", "pathologically nested TOML"],
)
def test_malformed_toml_values_exit_2_naming_the_field(edit, words, tmp_path, capsys):
    """Regression: these raised TypeError and RecursionError tracebacks."""
    path = tmp_path / "broken.toml"
    path.write_text(edit((MECHANISMS / "five_bar.toml").read_text()))
    assert main(["check", str(path)]) == 2
    err = _one_error(capsys)
    assert err.startswith(f"linkopt: error: {path}") and words in err


def test_an_internal_error_is_one_line_and_exit_3(monkeypatch, capsys):
    """A bug (not bad input) is one ``internal error`` line; ``--debug`` shows the
    traceback instead."""

    def broken(*args, **kwargs):
        raise ValueError("something\ninside broke")

    monkeypatch.setattr("linkopt._cli.mechanism.load", broken)
    path = str(MECHANISMS / "five_bar.toml")
    assert main(["check", path]) == 3
    err = _one_error(capsys)
    assert err.startswith("linkopt: internal error: ValueError: something inside")
    assert "--debug" in err
    with pytest.raises(ValueError, match="inside broke"):
        main(["--debug", "check", path])


def test_check_shows_collision_settings(capsys, tmp_path):
    """Regression (issue 44): ``check`` said nothing of ``[collision]``. The layered
    four-bar checks one pair (ground and coupler: the others share a joint, or are
    excluded) on two layers (the coupler lifted by 8 mm)."""
    layers = MECHANISMS.parent / "tests" / "data" / "four_bar_layers.toml"
    assert main(["check", str(layers), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)["collision"]
    assert info["enabled"] and info["clearance"] == 1.6 and info["weight"] == 1.0
    assert info["pairs"] == [["ground", "coupler"]] and info["layers"] == 2
    assert info["capsules"] == 4 and info["capsule_pairs"] == 1
    assert main(["check", str(layers)]) == 0
    line = next(
        ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("collision")
    )
    assert line.startswith("collision: on, clearance 1.6 (file units), weight 1")
    assert "1 checked pair(s) (ground-coupler" in line and "2 layer(s)" in line
    off = tmp_path / "off.toml"
    off.write_text(layers.read_text().replace("enable = true", "enable = false"))
    assert main(["check", str(off), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["collision"]["enabled"] is False
    assert main(["check", str(off)]) == 0
    assert "collision: off (enable = false)" in capsys.readouterr().out
    assert main(["check", str(MECHANISMS / "five_bar.toml"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["collision"] is None
    assert main(["check", str(MECHANISMS / "five_bar.toml")]) == 0
    assert "collision: off (no [collision] table)" in capsys.readouterr().out
