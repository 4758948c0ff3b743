"""The on-disk cache of traced programs: written once, read back instead of tracing,
keyed by the mechanism's contents, the argument shapes and every source file of the
package (subfolders included), and rebuilt when an entry is corrupt."""

import dataclasses
import gc
import shutil
import warnings
import weakref

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._engine import programs
from linkopt._engine.model import fingerprint


def _program(mech):
    def program(m, x, y):
        return jnp.sin(x) * m.length_scale + y

    return program


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("LINKOPT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(programs, "PROGRAMS", {})
    return tmp_path / "cache" / "traces"


@pytest.fixture
def package(tmp_path):
    """A copy of the package's sources, to edit."""
    copy = tmp_path / "linkopt"
    shutil.copytree(
        programs.PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__")
    )
    return copy


def test_a_trace_is_written_then_read_back_without_tracing(
    five_bar, cache, monkeypatch
):
    x, y = jnp.linspace(0.0, 1.0, 5), jnp.asarray(2.0)
    expected = np.sin(np.linspace(0.0, 1.0, 5)) * five_bar.length_scale + 2.0
    np.testing.assert_allclose(
        programs.call("toy", five_bar, _program(five_bar), x, y), expected, rtol=1e-15
    )
    (entry,) = cache.glob("toy-*.jaxexport")
    monkeypatch.setattr(programs, "PROGRAMS", {})  # as a new process would start

    def no_tracing(*args, **kwargs):
        raise AssertionError("traced again although the entry was on disk")

    monkeypatch.setattr(programs.export, "export", no_tracing)
    np.testing.assert_allclose(
        programs.call("toy", five_bar, _program(five_bar), x, y), expected, rtol=1e-15
    )
    # another shape is another program
    monkeypatch.undo()
    monkeypatch.setenv("LINKOPT_CACHE_DIR", str(cache.parent))
    programs.call("toy", five_bar, _program(five_bar), jnp.zeros(3), y)
    assert len(list(cache.glob("toy-*.jaxexport"))) == 2


def test_a_program_known_on_disk_its_shapes_and_compiling_ahead(five_bar, cache):
    """``stored`` tells a traced program from one never traced (another shape is
    another program); ``output_shapes`` and ``compile_ahead`` trace it without running
    it, and the call after them gives the program's numbers."""
    x, y = jnp.linspace(0.0, 1.0, 5), jnp.asarray(2.0)
    assert not programs.stored("toy", five_bar, x, y)
    shapes = programs.output_shapes("toy", five_bar, _program(five_bar), x, y)
    assert (shapes.shape, shapes.dtype) == ((5,), jnp.float64)
    assert programs.stored("toy", five_bar, x, y)
    assert not programs.stored("toy", five_bar, jnp.zeros(3), y)
    programs.compile_ahead("toy", five_bar, _program(five_bar), jnp.zeros(3), y)
    assert programs.stored("toy", five_bar, jnp.zeros(3), y)
    expected = np.sin(np.linspace(0.0, 1.0, 5)) * five_bar.length_scale + 2.0
    np.testing.assert_allclose(
        programs.call("toy", five_bar, _program(five_bar), x, y), expected, rtol=1e-15
    )


def test_a_corrupt_entry_is_traced_again(five_bar, cache, monkeypatch):
    x, y = jnp.ones(4), jnp.asarray(0.5)
    programs.call("toy", five_bar, _program(five_bar), x, y)
    (entry,) = cache.glob("toy-*.jaxexport")
    entry.write_bytes(b"not a program")
    monkeypatch.setattr(programs, "PROGRAMS", {})
    got = programs.call("toy", five_bar, _program(five_bar), x, y)
    np.testing.assert_allclose(
        got, np.sin(1.0) * five_bar.length_scale + 0.5, rtol=1e-15
    )
    assert entry.read_bytes() != b"not a program"


def test_fingerprint_follows_contents_not_identity(five_bar):
    again = linkopt.load(MECHANISMS / "five_bar.toml")
    assert again is not five_bar and fingerprint(again) == fingerprint(five_bar)
    moved = dataclasses.replace(five_bar, source="elsewhere.toml")
    assert fingerprint(moved) == fingerprint(five_bar)
    looser = dataclasses.replace(
        five_bar, evaluation=dataclasses.replace(five_bar.evaluation, max_step=0.2)
    )
    assert fingerprint(looser) != fingerprint(five_bar)
    shifted = dataclasses.replace(five_bar, anchors=five_bar.anchors + 1e-9)
    assert fingerprint(shifted) != fingerprint(five_bar)


def test_the_source_digest_covers_every_file_of_the_package(package):
    """Path-independent, and changed by an edit or a new file at any depth: a
    non-recursive glob would miss the files in the subfolders."""
    before = programs.source_digest(package)
    assert before == programs.source_digest(programs.PACKAGE)
    assert list(package.glob("_design/*.py")) and list(package.glob("_arms/*/*.py"))
    for edited in ("_design/sampling.py", "_arms/trace/task.py", "_errors.py"):
        path = package / edited
        original = path.read_bytes()
        path.write_bytes(original + b"\n# edited\n")
        assert programs.source_digest(package) != before, edited
        path.write_bytes(original)
        assert programs.source_digest(package) == before, edited
    (package / "_engine" / "extra.py").write_text("VALUE = 1\n")
    assert programs.source_digest(package) != before
    (package / "_engine" / "extra.py").unlink()
    (package / "_design" / "notes.txt").write_text("not a source file\n")
    assert programs.source_digest(package) == before


def test_an_edit_in_a_subfolder_keys_a_new_program(
    five_bar, cache, package, tmp_path, monkeypatch
):
    """The same program, mechanism and shapes from a package whose ``_design`` folder
    was edited is traced and stored anew, not read back from the old entry."""
    edited = tmp_path / "edited" / "linkopt"
    shutil.copytree(package, edited)
    path = edited / "_design" / "evaluation.py"
    path.write_text(path.read_text() + "\n# edited\n")
    x, y = jnp.ones(3), jnp.asarray(1.0)
    for source, entries in ((package, 1), (edited, 2), (package, 2)):
        monkeypatch.setattr(programs, "PACKAGE", source)
        monkeypatch.setattr(programs, "PROGRAMS", {})  # as a new process would start
        programs.call("toy", five_bar, _program(five_bar), x, y)
        assert len(list(cache.glob("toy-*.jaxexport"))) == entries, source


def test_a_program_that_cannot_be_exported_warns_once_and_still_runs(
    five_bar, cache, monkeypatch
):
    """A host callback has no stable export: plain jit, and one warning naming it."""
    monkeypatch.setattr(programs, "UNEXPORTED", set())

    def program(m, x):
        doubled = jax.pure_callback(
            lambda v: 2.0 * np.asarray(v), jax.ShapeDtypeStruct(x.shape, x.dtype), x
        )
        return doubled + m.length_scale

    with pytest.warns(RuntimeWarning, match="'host' could not be exported"):
        got = programs.call("host", five_bar, program, jnp.ones(3))
    np.testing.assert_allclose(got, 2.0 + five_bar.length_scale)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        programs.call("host", five_bar, program, jnp.ones(4))  # no second warning
    assert not list(cache.glob("host-*.jaxexport"))


def test_every_shipped_program_exports(five_bar, monkeypatch):
    """The solves, σ_min, read-outs, rest checks, evaluation and partial gradient of
    a mechanism all go through jax.export (a fallback would trace in every process)."""
    from linkopt._design.evaluation import alpha_minus, evaluate
    from linkopt._design.partial import partial_gradient

    monkeypatch.setattr(programs, "UNEXPORTED", set())
    monkeypatch.setattr(programs, "PROGRAMS", {})
    mech = linkopt.load(MECHANISMS / "five_bar.toml")
    motors = np.array([[0.1, -0.1], [0.2, 0.0]])
    solution = linkopt.solve_fk(mech, motors)
    linkopt.f_sing(mech, solution.state)
    linkopt.output_values(mech, solution.state)
    linkopt.solve_bk(mech, np.asarray(linkopt.output_values(mech, solution.state)))
    linkopt.solve_fk_path(mech, motors)
    evaluation = evaluate(mech)
    partial_gradient(mech, mech.design.p0, evaluation, alpha_minus(mech))
    assert programs.UNEXPORTED == set()
    names = {name for name, *_ in programs.PROGRAMS}
    assert {"from_rest_fk", "sigmas", "read_outputs", "path_fk"} <= names


def test_the_program_table_does_not_keep_a_mechanism_alive(five_bar, cache):
    mech = dataclasses.replace(five_bar, source="copy.toml")
    programs.call("toy", mech, _program(five_bar), jnp.ones(2), jnp.asarray(1.0))
    gone = weakref.ref(mech)
    del mech
    gc.collect()
    assert gone() is None


def test_the_program_table_keeps_only_the_most_recently_used(
    five_bar, cache, monkeypatch
):
    """Each loaded executable holds hundreds of memory mappings, and a process that
    kept every program it used ran past Linux's 65,530 and crashed inside XLA; the
    table drops the least recently used, which load again from disk when needed."""
    monkeypatch.setattr(programs, "LIVE_PROGRAMS", 3)
    x, y = jnp.ones(2), jnp.asarray(1.0)
    for name in ("p0", "p1", "p2", "p0", "p3"):
        programs.call(name, five_bar, _program(five_bar), x, y)
    assert [name for name, *_ in programs.PROGRAMS] == ["p2", "p0", "p3"]
    again = programs.call("p1", five_bar, _program(five_bar), x, y)  # from disk
    np.testing.assert_allclose(again, np.sin(1.0) * five_bar.length_scale + 1.0)
    assert [name for name, *_ in programs.PROGRAMS] == ["p0", "p3", "p1"]
