"""Parameters on a bound (issue 44): an optimised design says which of its parameters
sit on a bound, within a stated share of their range; ``evaluate`` says it too."""

import json

import numpy as np
import pytest
from conftest import MECHANISMS

from linkopt._cli.main import main
from linkopt._design.on_bounds import BOUND_TOLERANCE, bounds_line, on_bounds


def test_on_bounds_names_each_parameter_within_the_tolerance(five_bar):
    d = five_bar.design
    assert d.names == ("base_x", "elbow_x", "elbow_y")
    assert on_bounds(five_bar) == {}  # the file's design is inside
    span = d.upper - d.lower
    design = np.array([d.upper[0], d.lower[1], d.p0[2]])
    design[1] += 0.5 * BOUND_TOLERANCE * span[1]  # inside the band
    found = on_bounds(five_bar, design)
    assert list(found) == ["base_x", "elbow_x"]
    assert found["base_x"] == {"bound": "upper", "value": 45.0, "limit": 45.0}
    assert found["elbow_x"]["bound"] == "lower"
    design[1] = d.lower[1] + 2 * BOUND_TOLERANCE * span[1]  # outside the band
    assert list(on_bounds(five_bar, design)) == ["base_x"]
    assert bounds_line({}) is None
    assert bounds_line(found).startswith(
        "2 parameter(s) on a bound (within 1e-06 of its range): "
        "base_x = 45 (upper bound), elbow_x = 10 (lower bound)"
    )


@pytest.mark.parametrize("as_json", [True, False])
def test_evaluate_design_reports_the_parameters_on_a_bound(as_json, capsys):
    argv = ["evaluate", str(MECHANISMS / "five_bar.toml"), "--design", "45,37,36"]
    assert main([*argv, "--json"] if as_json else argv) == 0
    out = capsys.readouterr().out
    if as_json:
        found = json.loads(out)["at_bounds"]
        assert found == {"base_x": {"bound": "upper", "value": 45.0, "limit": 45.0}}
    else:
        assert "  1 parameter(s) on a bound (within 1e-06 of its range): " in out
        assert "base_x = 45 (upper bound)" in out
