"""The bounded on-disk caches (``linkopt._cache``): atomic entries, least recently
used removed first, JAX's executables written through them, ``linkopt cache``."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from linkopt import _cache
from linkopt import _folders as folders
from linkopt._cli.main import main


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("LINKOPT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("LINKOPT_CACHE_SIZE_MB", raising=False)
    return tmp_path / "cache"


def fill(folder, names, size, start=1_000_000.0):
    """Entries of ``size`` bytes, each used one second after the one before."""
    folder.mkdir(parents=True, exist_ok=True)
    for k, name in enumerate(names):
        path = folder / name
        path.write_bytes(b"x" * size)
        os.utime(path, (start + k, start + k))


def test_the_least_recently_used_entries_go_first(cache, monkeypatch):
    monkeypatch.setenv("LINKOPT_CACHE_SIZE_MB", "1")  # 0.25 MB of traces
    names = [f"p{k}-key.jaxexport" for k in range(6)]
    fill(cache / "traces", names, 100_000)
    assert _cache.read_used(cache / "traces" / names[0]) is not None  # used now
    _cache.store("traces", cache / "traces" / "new-key.jaxexport", b"y" * 100)
    left = sorted(p.name for p in (cache / "traces").glob("*.jaxexport"))
    # 0.25 MB holds two old entries beside the new one: the two used last
    assert left == sorted([names[0], names[5], "new-key.jaxexport"])
    assert not list((cache / "traces").glob(".linkopt-tmp-*"))


def test_a_reader_never_sees_a_half_written_entry(cache):
    path = cache / "traces" / "p-key.jaxexport"
    _cache.store("traces", path, b"a" * 1000)
    before = path.stat().st_ino
    _cache.store("traces", path, b"b" * 2000)
    assert path.read_bytes() == b"b" * 2000 and path.stat().st_ino != before


@pytest.mark.parametrize("kind", ["executables", "traces"])
def test_an_entry_being_written_is_no_entry(cache, monkeypatch, kind):
    """While an entry is written, its temporary file is matched by no pattern of the
    cache, so it is neither counted nor evicted."""
    name = "k-cache" if kind == "executables" else "p-key.jaxexport"
    path = _cache.folder(kind) / name
    seen = []

    def replace(src, dst):
        matched = list(path.parent.glob(_cache.PATTERNS[kind]))
        seen.append((Path(src).name, matched, _cache.entries(kind)))
        return os_replace(src, dst)

    os_replace = os.replace
    monkeypatch.setattr(folders.os, "replace", replace)
    _cache.store(kind, path, b"x" * 100)
    ((temporary, matched, found),) = seen
    assert temporary.startswith(folders.TEMP_PREFIX) and matched == found == []
    assert temporary.endswith(folders.TEMP_SUFFIX) and name in temporary
    assert [e.path.name for e in _cache.entries(kind)] == [name]


def test_a_bad_size_limit_is_named(cache, monkeypatch, capsys):
    monkeypatch.setenv("LINKOPT_CACHE_SIZE_MB", "-3")
    assert main(["cache", "info"]) == 2
    assert "LINKOPT_CACHE_SIZE_MB" in capsys.readouterr().err
    with pytest.warns(RuntimeWarning, match="LINKOPT_CACHE_SIZE_MB"):
        _cache.store("traces", cache / "traces" / "p-key.jaxexport", b"z")
    assert (cache / "traces" / "p-key.jaxexport").read_bytes() == b"z"


def test_cache_info_and_clear(cache, capsys):
    fill(cache, ["a-cache", "b-cache"], 1000)
    fill(cache / "traces", ["p-key.jaxexport"], 500)
    # a killed writer's temporary file: not an entry, and removed by clear
    (cache / "traces" / ".linkopt-tmp-0a1b-q-key.jaxexport.partial").write_bytes(b"x")
    assert main(["cache", "info", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["kinds"]["executables"]["entries"] == 2
    assert info["kinds"]["executables"]["bytes"] == 2000
    assert info["kinds"]["traces"]["bytes"] == 500
    limits = sum(row["limit_bytes"] for row in info["kinds"].values())
    assert limits == pytest.approx(_cache.DEFAULT_MB * 2**20, abs=2)
    assert main(["cache", "clear"]) == 0
    assert "removed 2 executables, 1 traces" in capsys.readouterr().out
    assert not [p for p in cache.rglob("*") if p.is_file()]


def test_cache_info_says_whether_the_kernels_are_in_use(cache, capsys, monkeypatch):
    """The text form names the compiled kernels' state and, on a JAX whose cache
    linkopt bounds, does not claim that it is unbounded."""
    from linkopt import _kernels

    assert main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    expected = "in use" if _kernels.handlers() is not None else "not in use, plain JAX"
    assert f"compiled kernels: {expected}" in out
    assert f"running jaxlib {_kernels.running_jaxlib_version()}" in out
    assert "not bounded" not in out
    monkeypatch.setenv("LINKOPT_KERNELS", "0")
    assert main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    assert "not in use, plain JAX (turned off by LINKOPT_KERNELS=0" in out


def test_jax_writes_its_executables_through_the_bounded_cache(tmp_path):
    """In a fresh process: JAX's file cache is linkopt's, a compiled program lands in
    it as one whole entry, and a second process reads it back."""
    script = (
        "import jax, jax.numpy as jnp, linkopt\n"
        "from jax._src import compilation_cache as cc\n"
        "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0)\n"
        "f = jax.jit(lambda x: jnp.sin(x) @ x.T + 1.0)\n"
        "f(jnp.ones((40, 40))).block_until_ready()\n"
        "print(type(cc._cache).__name__, cc._cache._path)\n"
    )
    env = dict(os.environ, LINKOPT_CACHE_DIR=str(tmp_path / "c"))
    env.pop("LINKOPT_CACHE_SIZE_MB", None)
    run = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True,
        timeout=300, check=True,
    )  # fmt: skip
    assert run.stdout.split()[0] == "Executables"
    entries = list((tmp_path / "c").glob("*-cache"))
    assert entries and not list((tmp_path / "c").glob(".linkopt-tmp-*"))
    used = {p: p.stat().st_mtime for p in entries}
    time.sleep(0.05)
    subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True,
        timeout=300, check=True,
    )  # fmt: skip
    assert any(p.stat().st_mtime > used[p] for p in entries)  # read, marked used
