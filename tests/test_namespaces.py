"""The public namespaces (issue 29): ``linkopt.arms.codesign``, ``linkopt.arms.dh``,
``linkopt.arms.trace`` and ``linkopt.export`` give linkopt's top-level objects shorter
names, import no JAX until a name is used (and then configure it as the top-level
names do), and refuse an unknown name naming the module. The tables of the API
reference (docs/reference/api.md) are the specification read here.
"""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

import linkopt

ROOT = Path(__file__).resolve().parents[1]
API = ROOT / "docs" / "reference" / "api.md"
NAMESPACES = [
    "linkopt.arms.codesign",
    "linkopt.arms.dh",
    "linkopt.arms.trace",
    "linkopt.export",
    "linkopt.synthesis",
]
#: A row of a namespace's table: its name, and the top-level name linked to its entry.
ROW = re.compile(
    r"^\| `(linkopt\.[\w.]+)\.(\w+)` \| \[`linkopt\.(\w+)`\]\(#linkopt\.\3\) \|$", re.M
)


def _documented() -> dict[str, dict[str, str]]:
    """namespace -> {name: top-level name}, read off the API reference."""
    tables: dict[str, dict[str, str]] = {}
    for module, name, top in ROW.findall(API.read_text()):
        assert name not in tables.setdefault(module, {}), (module, name)
        tables[module][name] = top
    return tables


def _type_checking_imports(path: Path) -> dict[str, tuple[str, str]]:
    """name -> (module under linkopt, attribute) of the ``if TYPE_CHECKING:`` block."""
    block = next(
        node
        for node in ast.parse(path.read_text()).body
        if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING"
    )
    return {
        alias.asname or alias.name: (stmt.module, alias.name)
        for stmt in block.body
        for alias in stmt.names
    }


def test_the_reference_lists_every_name_of_every_namespace_once():
    tables = _documented()
    assert sorted(tables) == NAMESPACES
    for module, names in tables.items():
        namespace = importlib.import_module(module)
        assert sorted(names) == namespace.__all__, module
        assert set(namespace.__all__) <= set(dir(namespace)), module


def test_each_namespaced_name_is_the_top_level_object():
    for module, names in _documented().items():
        namespace = importlib.import_module(module)
        for name, top in names.items():
            assert getattr(namespace, name) is getattr(linkopt, top), (module, name)


def test_every_arm_and_export_name_has_its_family_namespace():
    """Each top-level name imported from ``_arms.<family>`` is in
    ``linkopt.arms.<family>``, each from ``_export`` in ``linkopt.export``."""
    expected: dict[str, set[str]] = {module: set() for module in NAMESPACES}
    top_level = _type_checking_imports(ROOT / "linkopt" / "__init__.py")
    for name, (module, _) in top_level.items():
        parts = module.split(".")
        if parts[0] == "_arms":
            expected[f"linkopt.arms.{parts[1]}"].add(name)
        elif parts[0] == "_export":
            expected["linkopt.export"].add(name)
        elif parts[0] == "_synth":
            expected["linkopt.synthesis"].add(name)
    tables = _documented()
    assert {module: set(tables[module].values()) for module in NAMESPACES} == expected


@pytest.mark.parametrize("module", NAMESPACES)
def test_the_type_checking_imports_name_the_same_objects(module):
    path = ROOT / Path(*module.split("."))
    path = path.with_suffix(".py")
    eager = _type_checking_imports(path)
    namespace = importlib.import_module(module)
    assert sorted(eager) == namespace.__all__
    for name, (source, attribute) in eager.items():
        private = importlib.import_module(f"linkopt.{source}")
        assert getattr(namespace, name) is getattr(private, attribute), name


@pytest.mark.parametrize("module", ["linkopt.arms", *NAMESPACES])
def test_an_unknown_name_is_refused_naming_the_module(module):
    namespace = importlib.import_module(module)
    message = f"^module '{re.escape(module)}' has no attribute 'solve_arm'$"
    with pytest.raises(AttributeError, match=message):
        namespace.solve_arm  # noqa: B018 - a top-level name only


def test_the_namespaces_import_no_jax_until_a_name_is_used():
    """In a fresh process: the namespaces, reached as attributes of ``linkopt`` or
    imported, list their names without importing JAX; the first name used, even one
    from a JAX-free module, configures JAX (float64) before JAX runs."""
    code = (
        "import sys, linkopt\n"
        "assert {'arms', 'export'} <= set(dir(linkopt))\n"
        "spaces = [linkopt.arms.codesign, linkopt.arms.dh, linkopt.export]\n"
        "import linkopt.arms.trace as trace\n"
        "assert set(dir(linkopt.arms)) >= {'codesign', 'dh', 'trace'}\n"
        "for space in [*spaces, trace]:\n"
        "    assert set(space.__all__) <= set(dir(space)), space\n"
        "loaded = sorted(m for m in sys.modules if m.split('.')[0] == 'jax')\n"
        "assert not loaded and 'linkopt._config' not in sys.modules, loaded[:5]\n"
        "settings = linkopt.arms.dh.DHSynthesisSettings\n"
        "assert 'linkopt._config' in sys.modules\n"
        "import jax\n"
        "assert jax.config.jax_enable_x64\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
