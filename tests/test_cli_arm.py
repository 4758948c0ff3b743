"""``linkopt arm design`` (and the argument checks the other ``linkopt arm`` commands
share), in-process: ``arm design`` exits 0 exactly when the returned arm is feasible
(else 1) and writes a ``design.toml`` the loader accepts; bad arguments exit 2 with one
``linkopt: error:`` line before any solving."""

import json

import pytest
from arm_tasks import TINY_ARM, reached_targets

import linkopt
from linkopt._cli.main import main

ARM = (
    TINY_ARM
    + """
[solver]
starts = 3
max_iterations = 100
waypoints_per_target = 2
"""
)


@pytest.fixture(scope="module")
def task_file(tmp_path_factory):
    """The tiny arm with two position targets reached by the design (0.1, 0.3)."""
    text = ARM + reached_targets(ARM, [0.1, 0.3], [[0.3, -0.5], [-0.4, 0.6]])
    path = tmp_path_factory.mktemp("task") / "tiny.toml"
    path.write_text(text)
    return path


def test_arm_design_exit_status_follows_feasibility_and_writes_a_loadable_file(
    task_file, tmp_path, capsys
):
    out = tmp_path / "run"
    status = main(["arm", "design", str(task_file), "--out", str(out), "--starts", "1"])
    summary = json.loads((out / "summary.json").read_text())
    assert status == (0 if summary["feasible"] else 1)
    assert len(summary["starts"]) == 1  # --starts overrides the task's 3
    mech = linkopt.load(out / "design.toml")
    assert mech.num_motors == 2
    assert "best: start 0" in capsys.readouterr().out


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--seed", "-1"], "--seed: expected a non-negative integer, got -1"),
        (["--starts", "0"], "--starts: expected a positive integer, got 0"),
        (["--starts", "-2"], "--starts: expected a positive integer, got -2"),
        (["--workers", "0"], "--workers: expected a positive integer, got 0"),
    ],
)
def test_arm_design_bad_arguments_exit_2_with_one_line(extra, words, tmp_path, capsys):
    status = main(
        [
            "arm",
            "design",
            str(tmp_path / "never_read.toml"),
            "--out",
            str(tmp_path / "run"),
        ]
        + extra
    )
    err = capsys.readouterr().err
    assert status == 2 and err == f"linkopt: error: {words}\n"
    assert not (tmp_path / "run").exists()


def test_arm_design_out_is_a_file_exits_2(task_file, tmp_path, capsys):
    clash = tmp_path / "taken"
    clash.write_text("a file, not a directory")
    assert main(["arm", "design", str(task_file), "--out", str(clash)]) == 2
    err = capsys.readouterr().err
    assert (
        err.startswith("linkopt: error: --out: cannot create the output directory")
        and err.count("\n") == 1
    )


@pytest.mark.parametrize(
    "command", [["manipulability", "points.csv"], ["trace", "task.toml"]]
)
def test_other_arm_commands_reject_a_negative_seed(command, tmp_path, capsys):
    assert main(["arm", *command, "--out", str(tmp_path / "run"), "--seed", "-1"]) == 2
    assert (
        capsys.readouterr().err
        == "linkopt: error: --seed: expected a non-negative integer, got -1\n"
    )


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--starts", "100000"], "--starts: 100000 exceeds the limit of 1000"),
        (["--workers", "1000"], "--workers: 1000 exceeds the limit of 64"),
    ],
)
def test_arm_design_unbounded_arguments_exit_2(extra, words, tmp_path, capsys):
    test_arm_design_bad_arguments_exit_2_with_one_line(extra, words, tmp_path, capsys)


def test_arm_simplify_min_joints_beyond_the_arm_exits_2(task_file, tmp_path, capsys):
    argv = ["arm", "simplify", str(task_file), "--out", str(tmp_path / "run")]
    assert main([*argv, "--min-joints", "3"]) == 2
    err = capsys.readouterr().err
    assert err == (
        "linkopt: error: --min-joints: expected at most the task's 2 joints, got 3\n"
    )
    assert not (tmp_path / "run").exists()


def test_arm_design_meaningless_task_exits_2(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(
        ARM.replace('name = "tiny"', 'name = "tiny"\npayload = -1.0')
        + "[[targets]]\nposition = [0.3, 0.1, 0.1]\n"
    )
    assert main(["arm", "design", str(path), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"linkopt: error: {path}: [task].payload: expected a payload (kg) >= 0, "
        "got -1.0\n"
    )


def test_an_earlier_simplifys_stage_files_go_with_the_staged_write(tmp_path):
    """Regression: a second ``arm simplify`` into the same folder left the earlier
    run's ``stage<k>_*`` files beside its own. The stage files of the folder are the
    obsolete ones of the staged write, which removes those the new run lacks."""
    from linkopt._cli.arm import stage_files
    from linkopt._folders import staged

    for name in ("stage0_arm.toml", "stage3_arm.toml", "stage3_path.png", "other.txt"):
        (tmp_path / name).write_text("earlier run\\n")
    (tmp_path / "stages_notes.txt").write_text("not a stage file\\n")
    earlier = stage_files(tmp_path)
    assert earlier == ["stage0_arm.toml", "stage3_arm.toml", "stage3_path.png"]
    with staged(tmp_path, "summary.json", obsolete=earlier) as stage:
        (stage / "stage0_arm.toml").write_text("new run\\n")
        (stage / "summary.json").write_text("{}\\n")
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == ["other.txt", "stage0_arm.toml", "stages_notes.txt", "summary.json"]
    assert (tmp_path / "stage0_arm.toml").read_text() == "new run\\n"
