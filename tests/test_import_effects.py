"""Importing linkopt is definitions only (issue 40): in a fresh process, ``import
linkopt`` changes no JAX option, no environment variable, no JAX function and no import
machinery; the first name that computes turns float64 on, the one documented exception
(:mod:`linkopt._config`), and nothing else; the compilation caches are configured only
by :func:`linkopt.use_cache`, through JAX's public options.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "linkopt"

#: Prints, as JSON, what each step changed: JAX options, environment variables, the
#: functions of JAX's compilation cache and FFI modules, ``sys.meta_path``.
SCRIPT = """
import json, os, sys
import jax
from jax._src import compilation_cache, xla_bridge
from jax._src.lib import xla_client

def functions(module):
    return {k: id(v) for k, v in vars(module).items() if callable(v)}

def snapshot():
    return {
        "options": {k: repr(v) for k, v in jax.config.values.items()},
        "environ": dict(os.environ),
        "functions": [functions(m) for m in
                      (compilation_cache, xla_bridge, xla_client, jax.ffi)],
        "meta_path": [repr(f) for f in sys.meta_path],
    }

def changes(before, after):
    return {
        "options": sorted(k for k in after["options"]
                          if before["options"].get(k) != after["options"][k]),
        "environ": sorted(set(before["environ"].items())
                          ^ set(after["environ"].items())),
        "functions": before["functions"] != after["functions"],
        "meta_path": before["meta_path"] != after["meta_path"],
    }

steps = {}
start = snapshot()
import linkopt
steps["import"] = changes(start, snapshot())
import linkopt.arms.dh, linkopt.export, linkopt.synthesis
dir(linkopt.export)
steps["namespaces"] = changes(start, snapshot())
mech = linkopt.load("mechanisms/five_bar.toml")
linkopt.solve_fk(mech, [0.1, 0.2])
steps["compute"] = changes(start, snapshot())
linkopt.use_cache(sys.argv[1])
steps["use_cache"] = changes(start, snapshot())
steps["cache_dir"] = jax.config.values["jax_compilation_cache_dir"]
print(json.dumps(steps))
"""


def _steps(tmp_path) -> dict:
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(tmp_path / "cache")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.splitlines()[-1])


def test_import_changes_nothing_and_computing_only_float64(tmp_path):
    steps = _steps(tmp_path)
    nothing = {"options": [], "environ": [], "functions": False, "meta_path": False}
    assert steps["import"] == nothing
    assert steps["namespaces"] == nothing
    # the documented exception: float64, on the first name that computes
    assert steps["compute"] == {**nothing, "options": ["jax_enable_x64"]}
    # the caches only when asked, through JAX's public options
    cache_options = {
        "jax_compilation_cache_dir",
        "jax_compilation_cache_max_size",
        "jax_persistent_cache_min_compile_time_secs",
    }
    assert set(steps["use_cache"]["options"]) - {"jax_enable_x64"} <= cache_options
    assert "jax_compilation_cache_dir" in steps["use_cache"]["options"]
    assert steps["use_cache"]["environ"] == []
    assert not steps["use_cache"]["functions"] and not steps["use_cache"]["meta_path"]
    assert steps["cache_dir"] == str(tmp_path / "cache" / "executables")


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _top_level_imports(path: Path, module: str) -> tuple[bool, set[str]]:
    """Whether ``path`` imports JAX at its top level, and the linkopt modules it
    imports there (``from . import x`` counts as ``x``)."""
    uses_jax, found = False, set()
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Import):
            for alias in node.names:
                uses_jax |= alias.name.split(".")[0] == "jax"
                found.add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                uses_jax |= (node.module or "").split(".")[0] == "jax"
                base = node.module or ""
            else:
                parts = package.split(".")
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join(parts + ([node.module] if node.module else []))
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return uses_jax, found


def test_every_module_that_imports_jax_imports_the_configuration_first():
    """float64 must be on before any array is made: every linkopt module that imports
    JAX at its top level reaches :mod:`linkopt._config` through its own top-level
    imports (or a parent package's), so importing any of them alone turns it on."""
    graph, uses = {}, {}
    for path in sorted(PACKAGE.rglob("*.py")):
        module = _module(path)
        uses[module], imports = _top_level_imports(path, module)
        parents = {".".join(module.split(".")[:k]) for k in range(1, module.count("."))}
        graph[module] = (imports | parents) & {
            _module(p) for p in PACKAGE.rglob("*.py")
        }

    def reaches(module: str, seen: set[str]) -> bool:
        if module == "linkopt._config":
            return True
        seen.add(module)
        return any(reaches(m, seen) for m in graph[module] - seen)

    missing = [m for m in graph if uses[m] and not reaches(m, set())]
    assert missing == []
    assert uses["linkopt._engine.kinematics"] and uses["linkopt._engine.dense"]


def test_a_module_imported_alone_finds_float64_on():
    code = (
        "import importlib, jax\n"
        "for name in ('linkopt._engine.dense', 'linkopt._engine.joints',\n"
        "             'linkopt._design.metrics', 'linkopt._arms.chain'):\n"
        "    importlib.import_module(name)\n"
        "assert jax.config.jax_enable_x64\n"
        "assert jax.config.values['jax_compilation_cache_dir'] is None\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
        timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
