"""``linkopt export`` on the command line (issue 18): each format writes a file its tool
loads, ``--design`` is the design exported, and bad arguments exit 2 with one line
before anything is written."""

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
import trimesh
import yourdfpy

from linkopt._cli.main import main

ROOT = Path(__file__).resolve().parent.parent
FIVE_BAR = str(ROOT / "mechanisms" / "five_bar.toml")
ARM = str(ROOT / "tests" / "data" / "arm_3r.toml")


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_mjcf_of_a_design(five_bar, tmp_path, capsys):
    design = five_bar.design.p0 + 0.25 * (five_bar.design.upper - five_bar.design.p0)
    text = ",".join(f"{v:.17g}" for v in design)
    out = tmp_path / "sub" / "five_bar.xml"
    code, printed, err = _run(
        capsys, "export", FIVE_BAR, "--format", "mjcf", "--out", out,
        "--design", text, "--json",
    )  # fmt: skip
    assert code == 0, err
    summary = json.loads(printed)
    assert summary["format"] == "mjcf" and summary["seconds"] >= 0
    model = mujoco.MjModel.from_xml_path(str(out))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    # the tip at rest of the exported design (file anchors moved by the design)
    from linkopt._export.tree import rest

    tip = rest(five_bar, design).anchors[five_bar.joint_names.index("tip")] * 1e-3
    assert np.abs(data.site("ee").xpos - tip).max() < 1e-15


def test_urdf_glb_stl(tmp_path, capsys):
    code, printed, err = _run(
        capsys, "export", ARM, "--format", "urdf", "--out", tmp_path / "arm.urdf"
    )
    assert code == 0, err
    assert printed.startswith(f"wrote {tmp_path / 'arm.urdf'} (urdf: ")
    robot = yourdfpy.URDF.load(str(tmp_path / "arm.urdf"), load_meshes=False)
    assert robot.actuated_joint_names == ["yaw", "shoulder", "elbow"]
    code, _, err = _run(
        capsys, "export", FIVE_BAR, "--format", "glb", "--out", tmp_path / "f.glb",
        "--thickness", "3",
    )  # fmt: skip
    assert code == 0, err
    assert len(trimesh.load(tmp_path / "f.glb", force="scene").geometry) == 5
    code, _, err = _run(
        capsys, "export", FIVE_BAR, "--format", "stl", "--out", tmp_path / "parts"
    )
    assert code == 0, err
    assert len(list((tmp_path / "parts").glob("*.stl"))) == 5


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--format", "step", "--out", "x.step"], "invalid choice: 'step'"),
        (["--format", "urdf", "--out", "x.urdf"], "as MJCF"),
        (["--format", "stl", "--out", "d", "--thickness", "0"], "--thickness"),
        (["--format", "glb", "--out", "x.glb", "--thickness", "-2"], "--thickness"),
        (["--format", "glb", "--out", "x.glb", "--thickness", "nan"], "--thickness"),
        (["--format", "mjcf", "--out", "x.xml", "--thickness", "thin"], "thickness"),
        (["--format", "stl", "--out", "all.stl"], "one <body>.stl per body"),
        (["--format", "mjcf", "--out", "x.xml", "--design", "1,2"], "--design"),
        (["--format", "mjcf"], "--out"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(extra, message, tmp_path, capsys):
    extra = [
        str(tmp_path / e) if e.startswith(("x.", "d", "all.")) else e for e in extra
    ]
    code, printed, err = _run(capsys, "export", FIVE_BAR, *extra)
    assert code == 2 and printed == ""
    assert len(err.strip().splitlines()) == 1 and message in err
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_unwritable_out_exits_2(tmp_path, capsys):
    blocker = tmp_path / "file.txt"
    blocker.write_text("not a folder")
    for fmt, out in (("mjcf", blocker / "x.xml"), ("stl", blocker / "parts")):
        code, _, err = _run(capsys, "export", FIVE_BAR, "--format", fmt, "--out", out)
        assert code == 2 and len(err.strip().splitlines()) == 1 and "--out" in err
    code, _, err = _run(
        capsys, "export", FIVE_BAR, "--format", "mjcf", "--out", tmp_path
    )
    assert code == 2 and "is a directory" in err


def test_thickness_with_urdf_is_refused(capsys, tmp_path):
    code, _, err = _run(
        capsys, "export", ARM, "--format", "urdf", "--out", tmp_path / "a.urdf",
        "--thickness", "2",
    )  # fmt: skip
    assert code == 2 and "--thickness" in err
