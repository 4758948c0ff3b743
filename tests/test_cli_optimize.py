"""``linkopt optimize``: bad settings exit 2 with one line before any run starts; a
run that ends with no verified design exits 1 and says so."""

import json

import pytest
from conftest import MECHANISMS

from linkopt._cli.main import main


@pytest.mark.parametrize(
    "flags",
    [
        ["--seed", "-1"],
        ["--particles", "0"],
        ["--tolerance", "0"],
        ["--improvement", "1"],
        ["--resolution", "0"],
        ["--particles", "1000000000"],
        ["--workers", "1000000"],
        ["--verify-rounds", "-1"],
    ],
)
def test_optimize_command_rejects_bad_settings_with_one_line(flags, tmp_path, capsys):
    assert (
        main(
            [
                "optimize",
                str(MECHANISMS / "five_bar.toml"),
                "--out",
                str(tmp_path / "run"),
                *flags,
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("linkopt: error: --"), err
    assert not (tmp_path / "run").exists()


def test_a_run_that_ends_unverified_exits_one_and_says_so(
    tmp_path, monkeypatch, capsys
):
    """The run and its outputs are stood in for (they have their own tests): only the
    exit status and the message on an unverified result are under test here."""
    import linkopt._design.run as run

    summary = {
        "iterations": 1,
        "f_design": 3.0,
        "regularizer": 0.0,
        "verified": False,
        "initial_verified": False,
        "verification_rounds": [],
        "capped_samples": {"ik": 0, "adversarial": 0},
        "design": {"base_x": 45.0},
        "at_bounds": {"base_x": {"bound": "upper", "value": 45.0, "limit": 45.0}},
        "optimized_file": str(tmp_path / "run" / "optimized.toml"),
    }
    monkeypatch.setattr(run, "optimize", lambda *args, **kwargs: None)
    monkeypatch.setattr(run, "write_outputs", lambda *args, **kwargs: summary)
    out = tmp_path / "run"
    assert main(["optimize", str(MECHANISMS / "five_bar.toml"), "--out", str(out)]) == 1
    captured = capsys.readouterr()
    assert json.loads(captured.out)["at_bounds"] == summary["at_bounds"]
    err = captured.err.strip().splitlines()
    assert err[-1].startswith("linkopt: error: the optimised design does not pass")
    assert str(out / "verification.json") in err[-1]
    # the final report names the parameters on a bound (issue 44)
    assert err[-2] == (
        "linkopt: note: 1 parameter(s) on a bound (within 1e-06 of its range): "
        "base_x = 45 (upper bound); the optimum may lie beyond it"
    )


def test_the_figures_line_names_only_the_figures_written(tmp_path, monkeypatch, capsys):
    """A mechanism without space maps (more than three motors) gets no
    ``spaces_optimized.png``; the run's last lines must not name it."""
    import linkopt._design.run as run

    out = tmp_path / "run"

    def outputs(*args, **kwargs):
        out.mkdir(parents=True, exist_ok=True)
        for name in ("convergence.png", "mechanism.png"):
            (out / name).write_bytes(b"")
        return {
            "iterations": 1,
            "f_design": 0.0,
            "regularizer": 0.0,
            "verified": True,
            "initial_verified": True,
            "verification_rounds": [],
            "capped_samples": {"ik": 0, "adversarial": 0},
            "design": {},
            "at_bounds": {},
            "optimized_file": str(out / "optimized.toml"),
        }

    monkeypatch.setattr(run, "optimize", lambda *args, **kwargs: None)
    monkeypatch.setattr(run, "write_outputs", outputs)
    assert main(["optimize", str(MECHANISMS / "five_bar.toml"), "--out", str(out)]) == 0
    line = next(
        x for x in capsys.readouterr().err.splitlines() if x.startswith("figures:")
    )
    assert line == f"figures: {out / 'convergence.png'}, {out / 'mechanism.png'}"
