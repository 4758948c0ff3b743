"""Where a test's time goes: tracing, lowering and XLA compilation, per test (opt-in).

Off by default. With ``LINKOPT_COMPILE_STATS=<file>`` set, ``tests/conftest.py``
registers this plugin: a listener on JAX's duration events (``jax.monitoring``) sums,
for each test (setup, call and teardown together), the seconds spent tracing
(``jaxpr_trace_duration``), lowering to MLIR (``jaxpr_to_mlir_module_duration``) and
compiling (``backend_compile_duration``), the number of each, the compilations served
from the disk cache (``cache_hits``), the process's CPU seconds and the wall seconds,
and the programs that took the most compile time (name, seconds, compilations). One
JSON line per test is appended to the file (each pytest-xdist worker appends its own
lines). Work done in a
subprocess the test starts (the command line, a cluster's workers) is not seen: its
CPU shows only in the parent's wall time.

``benchmarks/suite_compile.py`` runs test files cold with it and keeps the table.
"""

from __future__ import annotations

import collections
import json
import os
import time

import pytest

#: Programs listed per test, by compile seconds.
TOP = 4


class CompileStats:
    def __init__(self, path: str):
        self.path = path
        self.events: collections.Counter = collections.Counter()
        self.counts: collections.Counter = collections.Counter()
        self.programs: collections.Counter = collections.Counter()
        self.compiled: collections.Counter = collections.Counter()
        from jax import monitoring

        monitoring.register_event_duration_secs_listener(self._duration)
        monitoring.register_event_listener(self._event)

    def _duration(self, event: str, duration: float, **kwargs) -> None:
        name = event.rsplit("/", 1)[-1]
        self.events[name] += duration
        self.counts[name] += 1
        if name == "backend_compile_duration":
            self.programs[kwargs.get("fun_name") or "?"] += duration
            self.compiled[kwargs.get("fun_name") or "?"] += 1

    def _event(self, event: str, **kwargs) -> None:
        self.counts[event.rsplit("/", 1)[-1]] += 1

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(self, item, nextitem):
        self.events.clear()
        self.counts.clear()
        self.programs.clear()
        self.compiled.clear()
        cpu, wall = time.process_time(), time.perf_counter()
        yield
        record = {
            "test": item.nodeid,
            "cpu_s": round(time.process_time() - cpu, 2),
            "wall_s": round(time.perf_counter() - wall, 2),
            "compile_s": round(self.events["backend_compile_duration"], 2),
            "compiles": self.counts["backend_compile_duration"],
            "trace_s": round(self.events["jaxpr_trace_duration"], 2),
            "traces": self.counts["jaxpr_trace_duration"],
            "lower_s": round(self.events["jaxpr_to_mlir_module_duration"], 2),
            "cache_hits": self.counts["cache_hits"],
            "top": [
                [name, round(seconds, 2), self.compiled[name]]
                for name, seconds in self.programs.most_common(TOP)
            ],
        }
        with open(self.path, "a") as out:
            out.write(json.dumps(record) + "\n")


def register(config) -> None:
    """Register the plugin when ``$LINKOPT_COMPILE_STATS`` names a file."""
    path = os.environ.get("LINKOPT_COMPILE_STATS")
    if path:
        config.pluginmanager.register(CompileStats(path), "linkopt-compile-stats")
