"""Engine limits and settings defaults that the command line shows or checks, read
without importing the engine.

``--help``, a usage error and a flag out of range answer before JAX is imported (most
of a command's start-up), but the defaults and limits they name belong to the engine's
settings classes and modules, which import JAX. They are read here from those modules'
source: a literal assigned at module level (:func:`constant`), or the literal defaults
of a dataclass's fields (:func:`defaults`). Where the source is not at hand, or a value
is not a literal, the module is imported instead: slower, the same value.
``tests/test_cli_startup.py`` checks that no ``--help`` imports JAX and that every value
read here equals the imported one.
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import importlib
from pathlib import Path
from types import SimpleNamespace

PACKAGE = Path(__file__).resolve().parent.parent
_NOT_LITERAL = object()


def constant(module: str, name: str):
    """The value of ``name`` in linkopt's ``module`` (e.g. ``"_design.maps"``)."""
    value = _literals(module)[0].get(name, _NOT_LITERAL)
    if value is _NOT_LITERAL:
        return getattr(_imported(module), name)
    return value


def defaults(module: str, name: str) -> SimpleNamespace:
    """The field defaults of the dataclass ``name`` in linkopt's ``module``, as
    attributes."""
    fields = _literals(module)[1].get(name)
    if fields is None or _NOT_LITERAL in fields.values():
        instance = getattr(_imported(module), name)()
        fields = {
            f.name: getattr(instance, f.name) for f in dataclasses.fields(instance)
        }
    return SimpleNamespace(**fields)


def _imported(module: str):
    return importlib.import_module(f"{__package__.rpartition('.')[0]}.{module}")


@functools.cache
def _literals(module: str) -> tuple[dict, dict[str, dict]]:
    """The module-level assignments of ``module``'s source, and per class the
    annotated fields' defaults; a value that is not a literal is
    :data:`_NOT_LITERAL`. Both empty when the source cannot be read."""
    path = PACKAGE.joinpath(*module.split(".")).with_suffix(".py")
    try:
        tree = ast.parse(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, SyntaxError, ValueError):
        return {}, {}
    classes = {
        node.name: _assigned(node.body, fields=True)
        for node in tree.body
        if isinstance(node, ast.ClassDef)
    }
    return _assigned(tree.body, fields=False), classes


def _assigned(body: list, fields: bool) -> dict:
    """``name -> literal value`` of the simple assignments in ``body``; with
    ``fields``, of the annotated ones (a dataclass's fields, a field without a default
    counting as not literal)."""
    values = {}
    for node in body:
        if isinstance(node, ast.AugAssign) and isinstance(node.target, ast.Name):
            values[node.target.id] = _NOT_LITERAL  # changed after it was set
            continue
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            target, value = node.target.id, node.value
        elif (
            not fields
            and isinstance(node, ast.Assign)
            and len(node.targets) == 1
            and isinstance(node.targets[0], ast.Name)
        ):
            target, value = node.targets[0].id, node.value
        else:
            continue
        try:
            values[target] = _NOT_LITERAL if value is None else ast.literal_eval(value)
        except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
            values[target] = _NOT_LITERAL
    return values
