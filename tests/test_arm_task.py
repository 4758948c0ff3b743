"""Arm task files: the shipped tasks load; bad files give one line naming file and
field."""

from pathlib import Path

import pytest
from arm_tasks import TINY_ARM

from linkopt import MechanismFileError
from linkopt._arms.codesign.task import load_task, loads_task

ROOT = Path(__file__).resolve().parent.parent

GOOD = (
    TINY_ARM
    + """
[[targets]]
position = [0.3, 0.1, 0.1]
axis = [1.0, 0.0, 0.0]
"""
)


def test_good_task_builds_the_arm():
    task = loads_task(GOOD, "tiny.toml")
    assert task.arm.num_joints == 2
    assert task.arm.design_names == ("modules[0].z", "modules[2].length")
    assert task.weights["obstacle"] == 5000.0 and task.tolerances["position"] == 5e-4


@pytest.mark.parametrize(
    "name", ["backpack_arm.toml", "rover_arm.toml", "elimination_square.toml"]
)
def test_shipped_tasks_load(name):
    task = load_task(ROOT / "tasks" / name)
    assert task.arm.num_joints >= 2 and len(task.targets) >= 3


BAD_FIELDS = [
    (
        'type = "link"',
        'type = "elbow"',
        "modules[2].type: unknown module type 'elbow'",
    ),
    (
        "length = { min = 0.1, max = 0.5 }",
        "length = { min = 0.5, max = 0.1 }",
        "modules[2].length: needs min < max",
    ),
    (
        "twist = 1.5707963267948966",
        "twist = 'x'",
        "modules[2].twist: expected a finite number",
    ),
    ("mass = 0.2", "", "modules[2].mass: missing required field"),
    (
        "axis = [1.0, 0.0, 0.0]",
        "axis = [0.0, 0.0, 0.0]",
        "targets[0].axis: zero-length axis",
    ),
    (
        "position = [0.3, 0.1, 0.1]",
        "position = [0.3, 0.1]",
        "targets[0].position: expected a list of 3",
    ),
    (
        "torque_limit = 9.0",
        "torque_limit = -1.0",
        "[task].torque_limit: expected a positive number",
    ),
    (
        'type = "tool"\nlength = 0.2',
        'type = "joint"',
        "the last module, and only it, must be the 'tool'",
    ),
    (
        "[[targets]]",
        "[[obstacles]]\ntype = 'box'\ncenter = [0,0,0]\nsize = [1,1,1]\n[[targets]]",
        "[workspace]: missing table",
    ),
    (
        "[[targets]]",
        "[[obstacles]]\ntype = 'cone'\n[[targets]]",
        "obstacles[0].type: unknown obstacle type 'cone'",
    ),
    (
        "[[targets]]",
        "[weights]\npath = -3\n[[targets]]",
        "[weights].path: expected a number >= 0",
    ),
    (
        "[[targets]]",
        "[solver]\nstarts = 0.5\n[[targets]]",
        "[solver].starts: expected a positive integer",
    ),
    (
        "[[targets]]",
        "[solver]\nseed = -1\n[[targets]]",
        "[solver].seed: expected a non-negative integer",
    ),
    (
        'type = "link"',
        'type = ["link"]',
        "modules[2].type: unknown module type ['link']",
    ),
    (
        "[[targets]]",
        "[[obstacles]]\ntype = ['box']\n[[targets]]",
        "obstacles[0].type: unknown obstacle type ['box']",
    ),
    ("[task]", "workspace = 1\n[task]", "[workspace]: expected a table"),
    (
        "[[targets]]",
        "[[obstacles]]\ntype = 'box'\ncenter = [0,0,0]\nsize = [1,1,1]\n"
        "orientation = [[1,0,0],[0,1,0],[0,1,0]]\n"
        "[workspace]\nlower = [-1,-1,-1]\nupper = [1,1,1]\n[[targets]]",
        "obstacles[0].orientation: expected a 3x3 rotation matrix",
    ),
    (
        "[[targets]]",
        "[[obstacles]]\ntype = 'sphere'\ncenter = [0,0,0]\nradius = 1\n"
        "orientation = [[1,0,0],[0,1,0],[0,0,1]]\n"
        "[workspace]\nlower = [-1,-1,-1]\nupper = [1,1,1]\n[[targets]]",
        "orientation",
    ),
]


@pytest.mark.parametrize("old, new, where", BAD_FIELDS)
def test_bad_fields_name_file_and_field(old, new, where):
    assert old in GOOD
    with pytest.raises(MechanismFileError) as err:
        loads_task(GOOD.replace(old, new, 1), "tiny.toml")
    message = str(err.value)
    assert (
        message.startswith("tiny.toml: ") and where in message and "\n" not in message
    )


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(MechanismFileError, match="file not found"):
        load_task(tmp_path / "none.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[task\n")
    with pytest.raises(MechanismFileError, match="bad.toml: invalid TOML"):
        load_task(bad)


def test_non_utf8_file_is_one_line(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(GOOD.replace('"tiny"', '"caf\xe9"').encode("latin-1"))
    with pytest.raises(
        MechanismFileError, match="latin1.toml: cannot read file"
    ) as err:
        load_task(path)
    assert "\n" not in str(err.value)


def test_corrupt_mesh_obstacle_is_rejected_while_loading(tmp_path):
    (tmp_path / "rock.stl").write_bytes(
        b"solid rock\nthis is not an STL file\n\x00\x01"
    )
    mesh = (
        "[[obstacles]]\ntype = 'mesh'\npath = 'rock.stl'\n"
        "[workspace]\nlower = [-1, -1, -1]\nupper = [1, 1, 1]\n"
    )
    path = tmp_path / "task.toml"
    path.write_text(GOOD + mesh)
    with pytest.raises(MechanismFileError) as err:
        load_task(path)
    message = str(err.value)
    assert message.startswith(f"{path}: obstacles[0].path: ") and "\n" not in message


def test_box_orientation_is_read_as_rows():
    text = GOOD.replace(
        "[[targets]]",
        "[[obstacles]]\ntype = 'box'\ncenter = [0.5,0,0]\nsize = [0.1,0.2,0.3]\n"
        "orientation = [[0,-1,0],[1,0,0],[0,0,1]]\n"
        "[workspace]\nlower = [-1,-1,-1]\nupper = [1,1,1]\n[[targets]]",
        1,
    )
    (box,) = loads_task(text, "tiny.toml").obstacles
    assert box.orientation == ((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
