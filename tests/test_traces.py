"""The on-disk cache of traced programs: written once, read back instead of tracing,
keyed by the mechanism's contents and the argument shapes, and rebuilt when an entry is
corrupt."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._engine import programs as _traces


def _program(mech):
    return lambda x, y: jnp.sin(x) * mech.length_scale + y


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("LINKOPT_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(_traces, "_PROGRAMS", {})
    return tmp_path / "traces"


def test_a_trace_is_written_then_read_back_without_tracing(
    five_bar, cache, monkeypatch
):
    x, y = jnp.linspace(0.0, 1.0, 5), jnp.asarray(2.0)
    expected = np.sin(np.linspace(0.0, 1.0, 5)) * five_bar.length_scale + 2.0
    np.testing.assert_allclose(
        _traces.call("toy", five_bar, _program(five_bar), x, y), expected, rtol=1e-15
    )
    (entry,) = cache.glob("toy-*.jaxexport")
    monkeypatch.setattr(_traces, "_PROGRAMS", {})  # as a new process would start

    def no_tracing(*args, **kwargs):
        raise AssertionError("traced again although the entry was on disk")

    monkeypatch.setattr(_traces.export, "export", no_tracing)
    np.testing.assert_allclose(
        _traces.call("toy", five_bar, _program(five_bar), x, y), expected, rtol=1e-15
    )
    # another shape is another program
    monkeypatch.undo()
    monkeypatch.setenv("LINKOPT_CACHE_DIR", str(cache.parent))
    _traces.call("toy", five_bar, _program(five_bar), jnp.zeros(3), y)
    assert len(list(cache.glob("toy-*.jaxexport"))) == 2


def test_a_corrupt_entry_is_traced_again(five_bar, cache, monkeypatch):
    x, y = jnp.ones(4), jnp.asarray(0.5)
    _traces.call("toy", five_bar, _program(five_bar), x, y)
    (entry,) = cache.glob("toy-*.jaxexport")
    entry.write_bytes(b"not a program")
    monkeypatch.setattr(_traces, "_PROGRAMS", {})
    got = _traces.call("toy", five_bar, _program(five_bar), x, y)
    np.testing.assert_allclose(
        got, np.sin(1.0) * five_bar.length_scale + 0.5, rtol=1e-15
    )
    assert entry.read_bytes() != b"not a program"


def test_fingerprint_follows_contents_not_identity(five_bar):
    again = linkopt.load(MECHANISMS / "five_bar.toml")
    assert again is not five_bar and _traces.fingerprint(again) == _traces.fingerprint(
        five_bar
    )
    moved = dataclasses.replace(five_bar, source="elsewhere.toml")
    assert _traces.fingerprint(moved) == _traces.fingerprint(five_bar)
    looser = dataclasses.replace(
        five_bar, evaluation=dataclasses.replace(five_bar.evaluation, max_step=0.2)
    )
    assert _traces.fingerprint(looser) != _traces.fingerprint(five_bar)
    shifted = dataclasses.replace(five_bar, anchors=five_bar.anchors + 1e-9)
    assert _traces.fingerprint(shifted) != _traces.fingerprint(five_bar)
