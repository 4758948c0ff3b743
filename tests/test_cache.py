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
    fill(cache / "executables", ["a-cache", "b-cache"], 1000)
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
    fill(cache, ["old-cache"], 10)  # an older layout's executable: cleared too
    assert main(["cache", "clear"]) == 0
    assert "removed 3 executables, 1 traces" in capsys.readouterr().out
    left = [p for p in cache.rglob("*") if p.is_file() and p.name != ".lockfile"]
    assert not left  # JAX's lock file stays: another process may hold it


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


def test_jax_keeps_its_executables_bounded_where_asked(tmp_path, monkeypatch):
    """In a fresh process: without :func:`linkopt.use_cache` nothing is written;
    with it JAX's own bounded cache (its public options) writes each compiled program
    with its last-use file, and a second process reads it back and marks it used."""
    script = (
        "import sys, jax, jax.numpy as jnp, linkopt\n"
        "if sys.argv[1] == 'cache':\n"
        "    linkopt.use_cache()\n"
        "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0)\n"
        "f = jax.jit(lambda x: jnp.sin(x) @ x.T + 1.0)\n"
        "f(jnp.ones((40, 40))).block_until_ready()\n"
        "print(jax.config.values['jax_compilation_cache_max_size'])\n"
    )
    env = dict(os.environ, LINKOPT_CACHE_DIR=str(tmp_path / "c"))
    env.pop("LINKOPT_CACHE_SIZE_MB", None)

    def run(mode: str) -> str:
        return subprocess.run(
            [sys.executable, "-c", script, mode], env=env, capture_output=True,
            text=True, timeout=300, check=True,
        ).stdout  # fmt: skip

    assert run("none").split() == ["-1"] and not (tmp_path / "c").exists()
    assert int(run("cache")) == _cache.limit("executables")
    entries = list((tmp_path / "c" / "executables").glob("*-cache"))
    assert entries and all(
        p.with_name(p.name.replace("-cache", "-atime")).exists() for p in entries
    )
    monkeypatch.setenv("LINKOPT_CACHE_DIR", str(tmp_path / "c"))
    used = {e.path: e.used for e in _cache.entries("executables")}
    time.sleep(0.05)
    run("cache")
    assert any(e.used > used[e.path] for e in _cache.entries("executables"))


def test_executables_without_a_last_use_are_marked_then_ranked(cache):
    """Entries written before JAX bounded the cache (no ``-atime``) get one from
    their modification time, so JAX's eviction can rank them."""
    fill(cache / "executables", ["a-cache", "b-cache"], 100)
    assert _cache.mark_executables(cache / "executables") == 2
    assert _cache.mark_executables(cache / "executables") == 0
    found = _cache.entries("executables")
    assert [e.path.name for e in found] == ["a-cache", "b-cache"]
    assert [e.used for e in found] == pytest.approx([1_000_000.0, 1_000_001.0])
    assert _cache.trim("executables", keep=100) == 1
    assert sorted(p.name for p in (cache / "executables").glob("*-*")) == [
        "b-atime",
        "b-cache",
    ]
