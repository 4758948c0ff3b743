"""The package's layering, read off its import statements (no imports are executed).

The folders are listed in pipeline order and each imports only those before it; no
module imports another module's private (underscore) names; tests import only public or
module-public names. These are the properties a newcomer relies on when reading the
tree, so a change that breaks one fails here rather than in review.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "linkopt"
ROOT_MODULES = {"__init__", "__main__", "_errors", "_config"}
# folder -> the folders (and root modules) it may import from
ALLOWED = {
    "_engine": {"_engine", "root"},
    "_export": {"_engine", "_export", "root"},
    "_design": {"_engine", "_export", "_design", "root"},
    "_arms": {"_engine", "_arms", "root"},
    "_cli": {"_engine", "_export", "_design", "_arms", "_cli", "root"},
    "root": {"root", "_engine", "_export", "_design", "_arms", "_cli"},
}


def _folder(module: tuple[str, ...]) -> str:
    return "root" if len(module) == 1 else module[0]


def _module_of(path: Path) -> tuple[str, ...]:
    return path.relative_to(PACKAGE).with_suffix("").parts


def _imports(path: Path):
    """(target module parts, imported names) of every relative import in ``path``."""
    here = _module_of(path)
    package = here[:-1] if here[-1] != "__init__" else here[:-1]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level > 0:
            base = package[: len(package) - (node.level - 1)]
            target = base + tuple(node.module.split(".")) if node.module else base
            yield target, [alias.name for alias in node.names]


def _is_module(parts: tuple[str, ...]) -> bool:
    return PACKAGE.joinpath(*parts).with_suffix(".py").exists() or (
        PACKAGE.joinpath(*parts).is_dir()
    )


SOURCES = sorted(PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_each_folder_imports_only_the_folders_before_it(path):
    folder = _folder(_module_of(path))
    for target, names in _imports(path):
        for name in names:
            parts = target + (name,) if _is_module(target + (name,)) else target
            assert _folder(parts) in ALLOWED[folder], (
                f"{path.relative_to(ROOT)} imports {'.'.join(parts)}"
            )


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_imports_another_modules_private_names(path):
    for target, names in _imports(path):
        for name in names:
            private = name.startswith("_") and not name.startswith("__")
            if private and not _is_module(target + (name,)):
                raise AssertionError(
                    f"{path.relative_to(ROOT)} imports {name} from {'.'.join(target)}"
                )


@pytest.mark.parametrize(
    "path",
    sorted((ROOT / "tests").glob("*.py")) + sorted((ROOT / "benchmarks").glob("*.py")),
    ids=lambda p: p.name,
)
def test_tests_and_benchmarks_import_public_or_module_public_names(path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
            "linkopt"
        ):
            parts = tuple(node.module.split("."))[1:]
            for alias in node.names:
                private = alias.name.startswith("_") and not alias.name.startswith("__")
                assert not private or _is_module(parts + (alias.name,)), (
                    f"{path.name} imports {alias.name} from {node.module}"
                )
