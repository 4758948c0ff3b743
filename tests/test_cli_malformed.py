"""Malformed command lines: generated flag values, strings and CSV contents for
``check | fk | bk | evaluate | plot | verify`` on the shipped five-bar and the spatial
2-DOF neck. Every case exits 0, 1 or 2 (never 3, never an exception), and a 2 is one
line on stderr. Cases that would do real work are kept tiny or invalid, and the
limits on grids and CSV files are checked before anything is allocated."""

import json
import math

import numpy as np
import pytest
from conftest import MECHANISMS
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import linkopt
from linkopt._cli.main import main
from linkopt._cli.values import design_arg
from linkopt._design.maps import MAX_CELLS
from linkopt._design.verify import check_resolution

FIVE = str(MECHANISMS / "five_bar.toml")
NECK = str(MECHANISMS / "neck_2dof.toml")
NECK3 = str(MECHANISMS / "neck_3dof.toml")

SPECIAL = [
    "nan",
    "-inf",
    "inf",
    "1e308",
    "-1e308",
    "1e309",
    "1e-320",
    "0x10",
    "1_0",
    "",
    " ",
    "--1",
    "\u0661",
    "\u221e",
    "9" * 400,
    "0",
    "0.1",
    "-0.2",
]
numbers = st.one_of(
    st.sampled_from(SPECIAL),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**400), 10**400).map(str),
    st.text(alphabet="0123456789.,-+eE naif", max_size=12),
)
rows = st.lists(numbers, max_size=4).map(",".join)
csv_texts = st.lists(
    st.one_of(
        rows, st.sampled_from(["left,right", "x,y", "a,b", '"1,2",3', "\ufeffx,y"])
    ),
    max_size=5,
).map("\n".join)
not_ints = st.text(max_size=12).filter(lambda t: not _is_int(t))


@pytest.fixture(autouse=True)
def _loaded_once(monkeypatch):
    """The shipped files are loaded once (each load compiles a kernel): the commands'
    ``load`` is memoised for them, so an example costs its checks, not a load."""
    from linkopt._cli import evaluation, mechanism, values, verify

    cache = {}

    def load(path):
        if str(path) not in (FIVE, NECK, NECK3):
            return linkopt.load(path)
        if str(path) not in cache:
            cache[str(path)] = linkopt.load(path)
        return cache[str(path)]

    for module in (evaluation, mechanism, values, verify):
        monkeypatch.setattr(module, "load", load)


def _is_int(text: str) -> bool:
    try:
        int(text)
    except ValueError:
        return False
    return True


def _run(argv, capsys) -> int:
    code = main(argv)
    err = capsys.readouterr().err
    assert code in (0, 1, 2), err
    if code == 2:
        assert len(err.splitlines()) == 1, err
    return code


@given(mech=st.sampled_from([FIVE, NECK]), kind=st.sampled_from(["fk", "bk"]), row=rows)
def test_generated_rows_exit_0_1_or_2(mech, kind, row, capsys):
    flag = "--motors" if kind == "fk" else "--outputs"
    _run([kind, mech, flag, row], capsys)


@given(kind=st.sampled_from(["fk", "bk"]), text=csv_texts, extra=st.binary(max_size=8))
def test_generated_csv_files_exit_0_1_or_2(kind, text, extra, tmp_path, capsys):
    path = tmp_path / "values.csv"
    path.write_bytes(text.encode("utf-8") + extra)
    flag = "--motors" if kind == "fk" else "--outputs"
    _run([kind, FIVE, flag, str(path), "--max-rows", "3"], capsys)


@given(text=st.text(max_size=200), binary=st.binary(max_size=40))
def test_generated_mechanism_files_exit_0_or_2(text, binary, tmp_path, capsys):
    path = tmp_path / "m.toml"
    path.write_bytes(text.encode("utf-8") + binary)
    assert _run(["check", str(path)], capsys) in (0, 2)


designs = st.one_of(
    st.lists(numbers, min_size=0, max_size=4).map(",".join),
    st.sampled_from([NECK, "missing.toml", "25,37,1e308", "nan,37,36"]),
)


@given(design=designs)
def test_generated_designs_for_evaluate_exit_2(design, five_bar, capsys):
    mech = five_bar
    try:
        design_arg(mech, design)
    except linkopt.InputError:
        pass
    else:
        assume(False)  # a valid design would run the evaluation
    assert _run(["evaluate", FIVE, "--design", design], capsys) == 2


resolutions = st.one_of(
    st.integers(-(10**6), 7).map(str),
    st.integers(10**4, 10**30).map(str),
    not_ints,
)


@given(
    mech=st.sampled_from([FIVE, NECK]),
    resolution=resolutions,
    design=st.one_of(st.none(), designs),
    max_cells=st.one_of(st.none(), st.integers(-5, 10**12).map(str), not_ints),
)
def test_generated_plot_flags_exit_2(
    mech, resolution, design, max_cells, tmp_path, capsys
):
    out = tmp_path / "a_file"
    out.write_text("")  # --out is a file: the command never gets to plot
    argv = ["plot", mech, "--out", str(out), "--resolution", resolution]
    argv += [] if design is None else ["--design", design]
    argv += [] if max_cells is None else ["--max-cells", max_cells]
    assert _run(argv, capsys) == 2


@settings(max_examples=30)
@given(
    mech=st.sampled_from([FIVE, NECK]),
    resolution=st.one_of(st.just("2"), resolutions),
    design=st.one_of(st.none(), designs),
)
def test_generated_verify_flags_exit_0_1_or_2(mech, resolution, design, capsys):
    argv = ["verify", mech, "--resolution", resolution]
    if design is not None:
        argv += ["--design", design]
    _run(argv, capsys)


# ---------------------------------------------------------------------------------
# Regressions, one per fix.


@pytest.mark.parametrize(
    "argv, message",
    [
        (["verify", FIVE, "--resolution", "abc"], "argument --resolution: invalid int"),
        (["plot", FIVE], "the following arguments are required: --out"),
        (["fk", FIVE, "--motors", "1e308,0"], "left = 1e+308 is out of range"),
        (["fk", FIVE, "--motors", "9" * 300 + ",0"], "left = 1e+300 is out of"),
        (["bk", FIVE, "--outputs", "0," + "1" * 300], "y = 1.11111e+299 is out"),
        (["verify", FIVE, "--max-cells", "0"], "--max-cells: expected at least 1"),
        (["evaluate", FIVE, "--design", "dir.toml"], "no such mechanism file"),
    ],
)
def test_bad_flags_are_one_line_exit_2(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.splitlines()) == 1


@pytest.mark.parametrize(
    "argv",
    [
        ["fk", FIVE, "--motors", "--"],
        ["bk", FIVE, "--outputs=--"],
        ["evaluate", FIVE, "--design", "--"],
        ["plot", FIVE, "--out=--"],
        ["export", FIVE, "--format", "mjcf", "--out=--"],
    ],
    ids=["motors", "outputs", "design", "plot-out", "export-out"],
)
def test_an_option_whose_value_is_a_double_dash_is_a_usage_error(argv, capsys):
    """argparse strips a lone ``--`` value and handed the command an empty list (exit
    3, ``TypeError`` in ``Path``)."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert ": expected one argument" in err and len(err.splitlines()) == 1, err
    assert "linkopt " + argv[0] + ": error: argument --" in err


def test_fk_out_of_continuation_steps_says_so_not_a_singularity(capsys):
    """The four-bar's crank turns freely, but a solve walks at most 400 steps of 0.2
    rad: ``--motors 1000`` stopped at 80 rad, blamed on "no assembly past it on this
    branch, or a singularity"."""
    assert main(["fk", str(MECHANISMS / "four_bar.toml"), "--motors", "1000"]) == 1
    err = capsys.readouterr().err
    assert "at most 400 continuation steps of 0.2, so it moves at most 80" in err
    assert "singularity" not in err and len(err.splitlines()) == 1, err


@pytest.mark.parametrize("name", ["../../evil", "a/b", "a\\b"])
def test_an_stl_export_never_writes_outside_its_folder(name, tmp_path, capsys):
    """Each body is written to ``<out>/<body>.stl``: a body named ``../../evil``
    wrote ``evil.stl`` two folders above ``--out``."""
    text = (MECHANISMS / "four_bar.toml").read_text()
    path = tmp_path / "m.toml"
    path.write_text(text.replace('"crank"', json.dumps(name)))  # a TOML string
    out = tmp_path / "a" / "b" / "stl"
    assert main(["export", str(path), "--format", "stl", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{path}: bodies[1].name: " in err and len(err.splitlines()) == 1, err
    assert not list(tmp_path.rglob("*.stl"))


def test_a_huge_verify_grid_is_refused_with_its_estimate(capsys):
    assert main(["verify", FIVE, "--resolution", "100000"]) == 2
    err = capsys.readouterr().err
    assert "--resolution: 100000 points per output (2 outputs): 1e+10 grid cells" in err
    assert f"over the limit of {MAX_CELLS} cells (raise it with --max-cells)" in err
    assert main(["verify", NECK3, "--resolution", "100000"]) == 2
    assert "(3 outputs): 1e+15 grid cells" in capsys.readouterr().err


def test_a_raised_cell_limit_still_meets_the_memory_limit(capsys):
    argv = ["verify", FIVE, "--resolution", "100000", "--max-cells", str(10**12)]
    assert main(argv) == 2
    # the limit is half of this machine's memory (linkopt._machine.grid_memory_cap)
    from linkopt._design.settings import MAX_BYTES

    limit = f"over the memory limit of {MAX_BYTES / 2**30:.3g} GiB"
    assert limit in capsys.readouterr().err


def test_a_huge_plot_grid_is_refused_before_the_folder_is_made(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["plot", FIVE, "--out", str(out), "--resolution", "100000"]) == 2
    assert "--resolution: 100000 cells per axis" in capsys.readouterr().err
    assert not out.exists()


def test_a_csv_over_the_row_limit_is_refused(tmp_path, capsys):
    path = tmp_path / "m.csv"
    path.write_text("left,right\n" + "0,0\n" * 30)
    assert main(["fk", FIVE, "--motors", str(path), "--max-rows", "20"]) == 2
    assert "30 data rows, more than the limit of 20" in capsys.readouterr().err


def test_a_plot_label_with_a_slash_is_refused(tmp_path, capsys):
    argv = ["plot", FIVE, "--out", str(tmp_path), "--label", "../x"]
    assert main(argv) == 2
    assert "--label: expected a file-name part" in capsys.readouterr().err


def test_check_resolution_gives_the_default_and_refuses_bad_values(five_bar):
    assert check_resolution(five_bar) == 41
    assert check_resolution(five_bar, 21) == 21
    for bad in (0, 1, -3, 1.5, True, "5"):
        with pytest.raises(linkopt.InputError, match="^resolution: expected"):
            check_resolution(five_bar, bad)
    with pytest.raises(linkopt.InputError, match="over the limit of 100 cells"):
        check_resolution(five_bar, 11, max_cells=100)
    with pytest.raises(linkopt.InputError, match="^resolution: expected"):
        linkopt.verify(five_bar, resolution=0)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda m: linkopt.solve_fk(m, [0.1]), r"^motors: expected shape \(2,\) or"),
        (lambda m: linkopt.solve_bk(m, [[[0.0, 50.0]]]), r"^outputs: expected shape"),
        (lambda m: linkopt.solve_fk(m, np.zeros((0, 2))), r"got \(0, 2\)"),
        (lambda m: linkopt.solve_fk(m, [math.nan, 0.0]), "^motors: expected finite"),
        (lambda m: linkopt.solve_bk(m, [1e300, 0.0]), "^outputs: x = 1e.300 is out"),
        (lambda m: linkopt.solve_fk(m, "ab"), "^motors: expected an array of numbers"),
        (lambda m: linkopt.solve_fk_path(m, [0.1, 0.1]), r"\(T, 2\) with T >= 1"),
        (
            lambda m: linkopt.solve_fk(m, [0.1, 0.1], start=np.zeros(3)),
            r"^start: expected a homogenised state \(35,\), got \(3,\)",
        ),
        (
            lambda m: linkopt.solve_fk(m, [0.1, 0.1], design=[25.0, 37.0]),
            r"^design: expected shape \(3,\)",
        ),
        (
            lambda m: linkopt.sensitivity(m, linkopt.rest_state(m), "bad"),
            "^wrt: expected one of motors",
        ),
        (
            lambda m: linkopt.verify(m, [math.nan, 37.0, 36.0], 3),
            "^design: expected finite",
        ),
    ],
)
def test_the_api_names_the_bad_argument(five_bar, call, message):
    with pytest.raises(linkopt.InputError, match=message):
        call(five_bar)


def test_write_design_refuses_non_finite_values(five_bar, tmp_path):
    path = tmp_path / "w.toml"
    with pytest.raises(linkopt.InputError, match="^design: expected finite"):
        linkopt.write_design(five_bar, [math.nan, 37.0, 36.0], 1.0, path)
    with pytest.raises(linkopt.InputError, match="^alpha_minus: expected a finite"):
        linkopt.write_design(five_bar, five_bar.design.p0, math.inf, path)
    assert not path.exists()


def test_space_maps_need_two_motors_and_two_outputs():
    from linkopt._draw.plot_maps import space_maps

    one = linkopt.load(MECHANISMS / "jansen_1dof.toml")
    with pytest.raises(linkopt.InputError, match="space maps need 2 motors"):
        space_maps(one, None, 8)
