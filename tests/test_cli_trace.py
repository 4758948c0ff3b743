"""``linkopt arm trace``: a bad task file exits 2; with no design found it exits 1 and
draws the task alone under a safe file name; a small task writes the result, the
mechanism file (which ``linkopt check`` accepts) and the figures."""

import json

import numpy as np
from test_trace import HEAD, LINE, SMALL

from linkopt._arms.trace import synthesis
from linkopt._arms.trace.synthesis import TraceResult
from linkopt._cli.main import main
from linkopt._cli.trace import file_stem


def test_cli_reports_a_bad_task_file_with_status_2(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(HEAD + LINE.replace('"line"', '"spline"'))
    assert main(["arm", "trace", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert (
        err.startswith("linkopt: error: ")
        and "primitives[0].type" in err
        and len(err.splitlines()) == 1
    )


def test_cli_without_a_design_draws_the_task_under_a_safe_name(
    tmp_path, monkeypatch, capsys
):
    """No design found: exit 1, result.json and the task figure only; the task name's
    '/' does not reach the file name."""
    path = tmp_path / "task.toml"
    path.write_text((HEAD + LINE).replace('name = "', 'name = "a/', 1))
    monkeypatch.setattr(
        synthesis,
        "synthesize",
        lambda task, **_: TraceResult(task, None, None, None, 0.0, []),
    )
    assert main(["arm", "trace", str(path), "--out", str(tmp_path / "out")]) == 1
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert (
        len(written) == 2
        and "result.json" in written
        and written[0].startswith("a_")
        and written[0].endswith("_task.png")
    )


def test_cli_writes_result_mechanism_and_figures(tmp_path, capsys):
    task = tmp_path / "small.toml"
    task.write_text(SMALL)
    out = tmp_path / "out"
    assert (
        main(
            [
                "arm",
                "trace",
                str(task),
                "--out",
                str(out),
                "--restarts",
                "1",
                "--no-gif",
            ]
        )
        == 0
    )
    payload = json.loads((out / "result.json").read_text())
    assert (
        payload["success"]
        and payload["verification"]["passed"]
        and payload["n_links"] == 2
    )
    assert [p["type"] for p in payload["primitives"]] == ["line", "arc"]
    assert set(payload["primitives"][0]["critical_states"]) == {
        "initial",
        "final",
        "closest",
        "farthest",
    }
    assert (
        all((out / f).is_file() for f in payload["figures"])
        and len(payload["figures"]) == 3
    )
    assert main(["check", str(out / "arm.toml")]) == 0
    assert "2 links" in capsys.readouterr().out


def test_trace_file_names_are_safe_whatever_the_task_name():
    assert file_stem("rose") == "rose"
    assert file_stem("../a/b c") == "_a_b_c"
    assert file_stem("..") == "task"
    assert "/" not in file_stem("x/y") and np.all(
        [c not in file_stem("a:b*?") for c in ":*?"]
    )


def test_cli_refuses_unbounded_flags_before_work(tmp_path, capsys):
    task = tmp_path / "never_read.toml"
    for extra, words in (
        (["--restarts", "100000"], "--restarts: 100000 exceeds the limit of 1000"),
        (["--best-of", "1000"], "--best-of: 1000 exceeds the limit of 100"),
        (["--discretised", "1000000"], "--discretised: 1000000 exceeds the limit"),
    ):
        argv = ["arm", "trace", str(task), "--out", str(tmp_path / "o"), *extra]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"linkopt: error: {words}") and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_cli_refuses_absurd_task_values(tmp_path, capsys):
    for text, where in (
        (
            SMALL.replace("end = [0.3, 0.1]", "end = [1e308, 0.1]", 1),
            "primitives[0].end",
        ),
        (
            SMALL.replace("link_diameter = 0.02", "link_diameter = 1e-12"),
            "link_diameter",
        ),
        (SMALL.replace("radius = 0.03", "radius = -0.03"), "obstacles[0].radius"),
    ):
        path = tmp_path / "task.toml"
        path.write_text(text)
        assert main(["arm", "trace", str(path), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"linkopt: error: {path}: ") and where in err
        assert err.count("\n") == 1
