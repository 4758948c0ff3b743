"""Shared fixtures. Mechanisms are loaded once per session (loading compiles a
kernel)."""

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

import linkopt
from linkopt._config import COMPILER_OPTIONS

#: The tests keep compiled programs on disk, as the command line does (a test that
#: points ``$LINKOPT_CACHE_DIR`` elsewhere moves the traced programs with it).
linkopt.use_cache()

#: The tests' own ``jax.jit`` programs (references, checks) compile with the options of
#: linkopt's programs too: they compile faster and agree with them to round-off. Set
#: before JAX starts its backend, which reads ``XLA_FLAGS`` once; the test processes'
#: subprocesses inherit it.
os.environ["XLA_FLAGS"] = " ".join(
    [os.environ.get("XLA_FLAGS", "")]
    + [f"--{name}={str(value).lower()}" for name, value in COMPILER_OPTIONS.items()]
).strip()

#: Generated-input tests (hypothesis) are reproducible and bounded: the same examples
#: on every run, no example database, no deadline (the first example may compile).
settings.register_profile(
    "linkopt",
    derandomize=True,
    database=None,
    deadline=None,
    max_examples=60,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
settings.load_profile("linkopt")

#: Memory mappings of a test worker above which its compiled programs are dropped
#: after a test (Linux allows 65,530; each loaded XLA:CPU executable holds a few
#: hundred, and past the limit XLA aborts or segfaults while compiling or loading).
#: A worker runs hundreds of tests, each compiling programs of its own (the arm
#: programs and tests' own jits are not bounded by linkopt's program table), so this
#: keeps a worker far from the limit; dropped programs load again from the disk caches.
MAX_MAPS = 40_000


def _maps() -> int:
    try:
        with open("/proc/self/maps") as maps:
            return sum(1 for _ in maps)
    except OSError:  # not Linux: no such limit to keep under
        return 0


@pytest.fixture(autouse=True)
def _bounded_mappings():
    yield
    if _maps() > MAX_MAPS:
        import gc

        import jax

        from linkopt._engine import programs

        programs.PROGRAMS.clear()
        jax.clear_caches()
        gc.collect()


ROOT = Path(__file__).resolve().parent.parent
MECHANISMS = ROOT / "mechanisms"


@pytest.fixture(scope="session")
def five_bar() -> linkopt.Mechanism:
    return linkopt.load(MECHANISMS / "five_bar.toml")


@pytest.fixture(scope="session")
def five_bar_evaluation(five_bar):
    from linkopt._design.evaluation import evaluate

    return evaluate(five_bar)


#: ``linkopt optimize`` flags of the smallest run (two particles, one iteration).
TINY_OPTIMIZE = ["--particles", "2", "--iterations", "1"]


@pytest.fixture
def fresh_checkpoint(tmp_path, five_bar):
    """A run folder holding the checkpoint of a five-bar run that has not started, as
    ``linkopt optimize five_bar.toml`` with :data:`TINY_OPTIMIZE` writes it; returns
    the folder and the parsed checkpoint, for a test to spoil and write back."""
    import json

    from linkopt._design.optimizer import OptimizerSettings, start
    from linkopt._design.run import CHECKPOINT, save_checkpoint

    settings = OptimizerSettings(particles=2, iterations=1)
    out = tmp_path / "run"
    out.mkdir()
    save_checkpoint(out, start(five_bar, settings), five_bar, settings)
    return out, json.loads((out / CHECKPOINT).read_text())


def pytest_configure(config):
    """Per-test compile statistics, opt-in (``$LINKOPT_COMPILE_STATS``; see
    ``tests/_compile_stats.py``)."""
    from _compile_stats import register

    register(config)
