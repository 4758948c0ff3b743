"""The command line answers without JAX (issue 29), its imports arranged so (no import
hook: issue 40).

``--help`` of every command, a usage error, a flag out of range and a file that cannot
be read or is not TOML answer before the engine (and JAX, most of the start-up) is
imported; the defaults and limits the parser shows come from JAX-free settings modules
and are the engine's own objects. Importing :mod:`linkopt` imports
no JAX (what importing changes: ``tests/test_import_effects.py``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from conftest import MECHANISMS

from linkopt._cli import animate, grids, manipulability
from linkopt._cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "linkopt"
FIVE_BAR = str(ROOT / "mechanisms" / "five_bar.toml")
TASKS = ROOT / "tasks"
POINTS = str(TASKS / "curve_cos5t_sin3t_sint.csv")
TRACE_TASK = str(TASKS / "wipe_table.toml")
ARM_TASK = str(TASKS / "elimination_square.toml")
#: The commands that read a mechanism file, with the arguments each needs besides it.
MECHANISM_COMMANDS = {
    "check": [],
    "fk": ["--motors", "0,0"],
    "bk": ["--outputs", "0,0"],
    "evaluate": [],
    "plot": ["--out", "{tmp}/plot"],
    "verify": [],
    "optimize": ["--out", "{tmp}/run"],
    "sweep": ["--seeds", "0:2", "--out", "{tmp}/sweep"],
    "export": ["--format", "mjcf", "--out", "{tmp}/five_bar.xml"],
    "animate": ["--out", "{tmp}/motion.gif"],
    "assemble": ["--out", "{tmp}/assembled.toml"],
    "view": ["--out", "{tmp}/view.html"],
}

#: Runs ``linkopt`` (its ``main``, as ``python -m linkopt`` does) on each command line
#: in turn, output swallowed, and prints per line the exit status and whether JAX was
#: imported by then; stops at the first that imported it.
SCRIPT = """
import contextlib, io, json, sys
from linkopt._cli.main import main
results = []
for argv in json.loads(sys.argv[1]):
    with contextlib.redirect_stdout(io.StringIO()) as out, \\
            contextlib.redirect_stderr(io.StringIO()) as err:
        try:
            status = main(argv)
        except SystemExit as exit_:
            status = exit_.code
    results.append([argv, status, "jax" in sys.modules, err.getvalue()])
    if "jax" in sys.modules:
        break
print(json.dumps(results))
"""


def _python(code: str, *args: str) -> subprocess.CompletedProcess:
    """``python -c code args`` in a fresh process, in the repository root; asserts
    that it exits 0."""
    done = subprocess.run(
        [sys.executable, "-c", code, *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return done


def _command_paths(parser: argparse.ArgumentParser, path=()):
    """Every command of ``parser``: ``()``, ``("check",)``, ``("arm", "trace")``..."""
    yield path
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _command_paths(sub, (*path, name))


def _without_jax(argvs: list[list[str]]) -> list:
    """Each command line's ``[argv, status, jax imported, stderr]``, in a fresh
    process."""
    results = json.loads(_python(SCRIPT, json.dumps(argvs)).stdout)
    for argv, status, jax, err in results:
        assert not jax, f"linkopt {' '.join(argv)} imported jax (exit {status}: {err})"
    assert len(results) == len(argvs)
    return results


def test_python_m_linkopt_help_does_not_import_jax():
    code = (
        "import runpy, sys\n"
        "sys.argv = ['linkopt', '--help']\n"
        "try:\n"
        "    runpy.run_module('linkopt', run_name='__main__', alter_sys=True)\n"
        "except SystemExit as exit_:\n"
        "    assert exit_.code == 0, exit_.code\n"
        "heavy = sorted(m for m in sys.modules if m.split('.')[0] in\n"
        "               ('jax', 'jaxlib', 'scipy', 'matplotlib', 'pyswarms'))\n"
        "assert not heavy, heavy\n"
    )
    assert "usage: linkopt" in _python(code).stdout


def test_every_help_answers_without_jax():
    paths = list(_command_paths(build_parser()))
    assert ("optimize",) in paths and ("arm", "trace") in paths
    results = _without_jax([[*path, "--help"] for path in paths])
    assert all(status == 0 for _, status, _, _ in results)


def test_usage_errors_and_bad_flags_answer_without_jax(tmp_path):
    tmp = str(tmp_path)
    usage = [
        [],
        ["no-such-command"],
        ["check"],
        ["fk", FIVE_BAR],
        ["export", FIVE_BAR, "--format", "xyz", "--out", f"{tmp}/x"],
        ["optimize", FIVE_BAR, "--out", f"{tmp}/run", "--particles", "many"],
    ]
    optimize = ["optimize", FIVE_BAR, "--out", f"{tmp}/run"]
    sweep = ["sweep", FIVE_BAR, "--seeds", "0:2", "--out", f"{tmp}/sweep"]
    scheduler = ["--scheduler", "tcp://127.0.0.1:1", "--connect-timeout"]
    plot = ["plot", FIVE_BAR, "--out", f"{tmp}/plot"]
    animate = ["animate", FIVE_BAR, "--out"]
    dh = ["arm", "manipulability", POINTS, "--out", f"{tmp}/m"]
    trace = ["arm", "trace", TRACE_TASK, "--out", f"{tmp}/t"]
    flags = [  # (the flag the error names, the command line)
        ("--particles", [*optimize, "--particles", "0"]),
        ("--seed", [*optimize, "--seed", "-1"]),
        ("--resolution", [*optimize, "--resolution", "4"]),
        ("--connect-timeout", [*optimize, *scheduler, "0"]),
        ("--workers", [*sweep, "--workers", "0"]),
        ("--connect-timeout", [*sweep, *scheduler, "-1"]),
        ("--resolution", [*plot, "--resolution", "4"]),
        ("--label", [*plot, "--label", "a/b"]),
        ("--resolution", ["verify", FIVE_BAR, "--resolution", "1"]),
        ("--out", [*animate, f"{tmp}/motion.png"]),
        ("--frames", [*animate, f"{tmp}/m.gif", "--frames", "9", "--path", "p.csv"]),
        ("--starts", [*dh, "--starts", "0"]),
        ("--precision", [*dh, "--precision", "0"]),
        ("--restarts", [*trace, "--restarts", "0"]),
        ("--discretised", [*trace, "--discretised", "1"]),
        (
            "--workers",
            ["arm", "design", ARM_TASK, "--out", f"{tmp}/a", "--workers", "0"],
        ),
    ]
    results = _without_jax(usage + [argv for _, argv in flags])
    assert all(status == 2 for _, status, _, _ in results)
    for (argv, _, _, err), (flag, _) in zip(results[len(usage) :], flags):
        assert err.startswith(f"linkopt: error: {flag}: "), (argv, err)
    assert not any(tmp_path.iterdir())  # refused before anything was written


def test_unreadable_and_malformed_files_answer_without_jax(tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text("[mechanism\nname = 1\n")
    missing = str(tmp_path / "missing.toml")
    argvs, expected = [], []
    for command, extra in MECHANISM_COMMANDS.items():
        extra = [a.format(tmp=tmp_path) for a in extra]
        for path, words in ((missing, "file not found"), (str(broken), "invalid TOML")):
            argvs.append([command, path, *extra])
            expected.append(f"linkopt: error: {path}: {words}")
    argvs.append(["arm", "trace", missing, "--out", str(tmp_path / "t")])
    expected.append(f"linkopt: error: {missing}: ")
    for (argv, status, _, err), words in zip(_without_jax(argvs), expected):
        assert status == 2 and err.startswith(words), (argv, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.toml"]


def test_a_file_with_a_bad_field_answers_without_jax(tmp_path):
    """The fields are read and checked before anything computes: a user's first
    mistake in a file comes back without waiting for JAX (``bench_cli_startup``)."""
    text = (MECHANISMS / "four_bar.toml").read_text()
    cases = {
        "joints[0].type": text.replace('type = "revolute"', 'type = "hinge"', 1),
        "joints[0].bodies": text.replace('bodies = ["ground"', 'bodies = ["gnd"', 1),
        "[evaluation].samples_per_dimension": text
        + "\n[evaluation]\nsamples_per_dimension = 0\n",
    }
    argvs = []
    for k, body in enumerate(cases.values()):
        path = tmp_path / f"bad{k}.toml"
        path.write_text(body)
        argvs.append(["check", str(path)])
    results = _without_jax(argvs)
    for (argv, status, _, err), field in zip(results, cases):
        assert status == 2 and f"{argv[1]}: {field}" in err, (argv, err)


def _command(parser: argparse.ArgumentParser, *path: str) -> argparse.ArgumentParser:
    for name in path:
        action = next(
            a for a in parser._actions if isinstance(a, argparse._SubParsersAction)
        )
        parser = action.choices[name]
    return parser


def test_the_defaults_shown_are_the_engines():
    """The parser's defaults equal the settings classes' own (imported here)."""
    from linkopt import OptimizerSettings
    from linkopt._arms.dh import synthesis
    from linkopt._design import maps, motion
    from linkopt.arms.dh import DHSynthesisSettings
    from linkopt.arms.trace import TraceSettings

    parser = build_parser()
    optimizer = OptimizerSettings()
    for command, names in (
        ("optimize", ["particles", "iterations", "seed", "mode"]),
        ("sweep", ["particles", "iterations", "mode"]),
    ):
        names += ["tolerance", "patience", "improvement", "verify_rounds"]
        cmd = _command(parser, command)
        for name in names:
            assert cmd.get_default(name) == getattr(optimizer, name), (command, name)
    dh = DHSynthesisSettings()
    cmd = _command(parser, "arm", "manipulability")
    for option, name in (
        ("precision", "precision"),
        ("size_damping", "size_damping"),
        ("seed", "seed"),
        ("starts", "starts"),
        ("iterations", "max_iterations"),
    ):
        assert cmd.get_default(option) == getattr(dh, name), option
    trace = TraceSettings()
    cmd = _command(parser, "arm", "trace")
    assert cmd.get_default("restarts") == trace.restarts
    assert cmd.get_default("best_of") == trace.best_of
    for command in ("plot", "verify"):
        assert _command(parser, command).get_default("max_cells") == maps.MAX_CELLS
    assert animate.DEFAULT_FRAMES is motion.DEFAULT_FRAMES
    assert animate.MAX_FRAMES is motion.MAX_FRAMES
    assert manipulability.LIMITS is synthesis.LIMITS


def test_the_settings_the_command_line_reads_are_the_engines_own():
    """One class per settings, one object per limit: the JAX-free modules the parser
    reads hold what the engine and the public API use, not copies."""
    import linkopt
    from linkopt._arms.dh import synthesis
    from linkopt._arms.trace import synthesis as trace
    from linkopt._design import maps, optimizer

    assert optimizer.OptimizerSettings is linkopt.OptimizerSettings
    assert synthesis.DHSynthesisSettings is linkopt.arms.dh.DHSynthesisSettings
    assert trace.TraceSettings is linkopt.arms.trace.TraceSettings
    assert grids.MAX_CELLS is maps.MAX_CELLS


def test_import_linkopt_imports_no_jax_and_its_names_turn_float64_on():
    code = (
        "import sys, linkopt\n"
        "assert 'jax' not in sys.modules\n"
        "assert issubclass(linkopt.InputError, linkopt.LinkoptError)\n"
        "assert 'jax' not in sys.modules\n"
        "linkopt.Mechanism\n"
        "import jax\n"
        "assert jax.config.jax_enable_x64\n"
    )
    _python(code)
