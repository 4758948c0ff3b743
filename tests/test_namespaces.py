"""The public namespaces (issues 29, 40): ``linkopt.arms.codesign``,
``linkopt.arms.dh``, ``linkopt.arms.trace``, ``linkopt.export`` and
``linkopt.synthesis`` are the one home of their objects; the old top-level names give
the same objects with a ``DeprecationWarning`` naming the new name, and are no longer
listed in ``linkopt.__all__``. The namespaces import no JAX until a name is used (and
then turn float64 on as the top-level names do), and refuse an unknown name naming the
module. The tables of the API reference (docs/reference/api.md) are the specification
read here.
"""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
import warnings
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
#: A row of a namespace's table: its name, linked to its entry, and its old top-level
#: name.
ROW = re.compile(
    r"^\| \[`(linkopt\.[\w.]+)\.(\w+)`\]\(#\1\.\2\) \| `linkopt\.(\w+)` \|$", re.M
)


def _documented() -> dict[str, dict[str, str]]:
    """namespace -> {name: old top-level name}, read off the API reference."""
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


def test_each_old_top_level_name_warns_and_gives_the_namespaced_object():
    for module, names in _documented().items():
        namespace = importlib.import_module(module)
        for name, top in names.items():
            assert top not in linkopt.__all__, top
            new = f"{module}.{name}"
            with pytest.warns(DeprecationWarning, match=f"use {re.escape(new)}$"):
                old = getattr(linkopt, top)
            assert old is getattr(namespace, name), new


def test_the_deprecated_names_are_the_documented_ones():
    documented = {top for names in _documented().values() for top in names.values()}
    deprecated = set()
    for name in documented | {"solve_fk", "load"}:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            getattr(linkopt, name)
        if any(issubclass(w.category, DeprecationWarning) for w in caught):
            deprecated.add(name)
    assert deprecated == documented and len(documented) == 38


def test_the_top_level_keeps_no_namespace_object():
    """The top level's own imports name no module of the arm families, the exporters
    or synthesis."""
    top_level = _type_checking_imports(ROOT / "linkopt" / "__init__.py")
    families = {module.split(".")[0] for module, _ in top_level.values()}
    assert not families & {"_arms", "_export", "_synth"}, families


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
    from a JAX-free module, turns float64 on before JAX runs."""
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
