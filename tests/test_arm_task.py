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


MESH_WORKSPACE = "[workspace]\nlower = [-1, -1, -1]\nupper = [1, 1, 1]\n"
SPHERE = "[[obstacles]]\ntype = 'sphere'\ncenter = [2,2,2]\nradius = 0.1\n"

# Physically meaningless values and absurd magnitudes (issue 17): once read as a
# "feasible" task, now one line naming the field and what was expected.
MEANINGLESS = [
    (
        "[task]",
        "[task]\npayload = -0.5",
        "[task].payload: expected a payload (kg) >= 0",
    ),
    ("length = 0.2", "length = 0.0", "modules[4].length: expected a positive number"),
    ("length = 0.2", "length = -0.2", "modules[4].length: expected a positive number"),
    (
        "length = { min = 0.1, max = 0.5 }",
        "length = { min = -0.1, max = 0.5 }",
        "modules[2].length.min: expected a positive number",
    ),
    ("mass = 0.2", "mass = -0.2", "modules[2].mass: expected a mass >= 0"),
    ("mass = 0.2", "mass = 1e308", "modules[2].mass: expected a magnitude of at most"),
    (
        "twist = 1.5707963267948966",
        "twist = 1e9",
        "modules[2].twist: expected a magnitude of at most 12.5664 rad",
    ),
    (
        "torque_limit = 9.0",
        "torque_limit = 1e300",
        "[task].torque_limit: expected a positive number of at most",
    ),
    ("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, nan, -9.81]", "[task].gravity"),
    (
        "position = [0.3, 0.1, 0.1]",
        "position = [1e308, 0.1, 0.1]",
        "targets[0].position: expected coordinates of magnitude at most 1000",
    ),
    (
        "axis = [1.0, 0.0, 0.0]",
        "axis = [1e308, 1e308, 0.0]",
        "targets[0].axis: expected coordinates of magnitude",
    ),
    (
        "axis = [1.0, 0.0, 0.0]",
        "approach = { local = [1,0,0], direction = [0,0,-1], angle_deg = 400 }",
        "targets[0].approach.angle_deg: expected an angle in (0, 180]",
    ),
    (
        "[[targets]]",
        "[solver]\nstarts = 1000000\n[[targets]]",
        "[solver].starts: 1000000 exceeds the limit of 1000",
    ),
    (
        "[[targets]]",
        "[solver]\nwaypoints_per_target = 100\n[[targets]]\nposition = [0,0,0]\n"
        "[[targets]]\nposition = [0,0,0.1]\n[[targets]]\nposition = [0,0,0.2]\n"
        "[[targets]]\nposition = [0,0,0.3]\n[[targets]]\nposition = [0,0,0.4]\n"
        "[[targets]]\nposition = [0,0,0.5]\n[[targets]]\nposition = [0,0,0.6]\n"
        "[[targets]]\nposition = [0,0,0.7]\n[[targets]]\nposition = [0,0,0.8]\n"
        "[[targets]]\nposition = [0,0,0.9]\n[[targets]]\nposition = [0,0,1]\n"
        "[[targets]]",
        "[solver].waypoints_per_target: the NLP would have 2402 variables",
    ),
    (
        "[[targets]]",
        SPHERE + MESH_WORKSPACE + "voxel = 1e-5\n[[targets]]",
        "[workspace].voxel: voxel grid of 8e+15 cells (1.6e+06 TB) exceeds the limit "
        "of 2e+07 cells (4 GB)",
    ),
    (
        "[[targets]]",
        SPHERE
        + "[workspace]\nlower = [-1e3, -1e3, -1e3]\nupper = [1e3, 1e3, 1e3]\n"
        + "[[targets]]",
        "[workspace].voxel: voxel grid of 1e+15 cells",
    ),
    (
        "[[targets]]",
        SPHERE + MESH_WORKSPACE + "bogus = 1\n[[targets]]",
        "[workspace].bogus: unknown field",
    ),
    (
        "[[targets]]",
        "[[obstacles]]\ntype = 'sphere'\ncenter = [2,2,2]\nradius = -0.1\n"
        + MESH_WORKSPACE
        + "[[targets]]",
        "obstacles[0].radius: expected a positive number",
    ),
    ("mass = 0.2", "mass = 0.2\ntorque_limit = 3", "modules[2].torque_limit: unknown"),
    ('name = "tiny"', 'name = "tiny"\nmass = 1', "[task].mass: unknown field"),
]


@pytest.mark.parametrize("old, new, where", MEANINGLESS)
def test_meaningless_values_name_file_and_field(old, new, where):
    test_bad_fields_name_file_and_field(old, new, where)


def test_max_cells_raises_the_grid_limit():
    text = GOOD.replace(
        "[[targets]]", SPHERE + MESH_WORKSPACE + "voxel = 0.005\n[[targets]]", 1
    )
    with pytest.raises(MechanismFileError, match="exceeds the limit of 2e\\+07"):
        loads_task(text, "tiny.toml")
    raised = text.replace("voxel = 0.005", "voxel = 0.005\nmax_cells = 70000000")
    task = loads_task(raised, "tiny.toml")
    assert task.max_cells == 70_000_000 and task.voxel == 0.005


def test_oversized_task_file_is_refused_before_reading(tmp_path):
    path = tmp_path / "big.toml"
    path.write_text(GOOD + "#" * (17 * 2**20))
    with pytest.raises(MechanismFileError, match="big.toml: task file of 17.0 MiB"):
        load_task(path)


@pytest.mark.parametrize(
    "content, words",
    [
        (b"", "holds no triangle mesh"),
        (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "not a closed (watertight) surface"),
    ],
)
def test_empty_or_open_mesh_obstacle_is_rejected(tmp_path, content, words):
    (tmp_path / "rock.obj").write_bytes(content)
    mesh = "[[obstacles]]\ntype = 'mesh'\npath = 'rock.obj'\n" + MESH_WORKSPACE
    path = tmp_path / "task.toml"
    path.write_text(GOOD + mesh)
    with pytest.raises(MechanismFileError) as err:
        load_task(path)
    message = str(err.value)
    assert message.startswith(f"{path}: obstacles[0].path: ") and words in message


def test_shipped_tasks_read_as_before():
    task = load_task(ROOT / "tasks" / "rover_arm.toml")
    assert task.voxel == 0.02 and task.clearance == 0.04 and task.payload == 0.1
    assert task.solver == {
        "starts": 8,
        "seed": 0,
        "max_iterations": 1500,
        "waypoints_per_target": 4,
    }
    assert len(task.obstacles) == 6 and task.arm.num_design == 9
