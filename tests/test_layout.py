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
    # the compiled kernels (linkopt._kernels): below everything, importing nothing
    "_kernels": {"_kernels"},
    "_engine": {"_kernels", "_engine", "root"},
    "_files": {"_engine", "_files", "root"},
    "_export": {"_engine", "_files", "_export", "root"},
    "_design": {"_engine", "_files", "_export", "_design", "root"},
    "_arms": {"_engine", "_files", "_arms", "root"},
    # synthesis: a second job on the design layer's machinery
    "_synth": {"_engine", "_files", "_export", "_design", "_synth", "root"},
    # drawing: figures, maps, animations, the browser view; above every computation
    "_draw": {
        "_engine",
        "_files",
        "_export",
        "_design",
        "_arms",
        "_synth",
        "_draw",
        "root",
    },
    "_cli": {
        *("_engine", "_files", "_export", "_design", "_arms", "_synth", "_draw"),
        *("_cli", "root"),
    },
    "root": {
        *("root", "_engine", "_files", "_export", "_design", "_arms", "_synth"),
        *("_draw", "_cli"),
    },
    # the public namespaces (``linkopt.arms.*``; ``linkopt.export`` is a root module)
    "arms": {"_arms", "arms", "root"},
}
# a diagnostic (``linkopt cache info``) may ask the kernels whether they are there
ALLOWED["_cli"].add("_kernels")
ALLOWED["root"].add("_kernels")


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


def _module_names(tree: ast.Module, path: Path) -> set[str]:
    """Names that ``path`` binds to linkopt modules (``import linkopt.x as y``,
    ``from linkopt._engine import programs``, ``from . import dense``)."""
    here = _module_of(path) if path.is_relative_to(PACKAGE) else None
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "linkopt":
                    names.add(alias.asname or alias.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0 and (node.module or "").split(".")[0] == "linkopt":
                base = tuple(node.module.split("."))[1:]
            elif node.level > 0 and here is not None:
                package = here[:-1]
                base = package[: len(package) - (node.level - 1)]
                base += tuple(node.module.split(".")) if node.module else ()
            else:
                continue
            for alias in node.names:
                if _is_module(base + (alias.name,)):
                    names.add(alias.asname or alias.name)
    return names


@pytest.mark.parametrize(
    "path",
    SOURCES
    + sorted((ROOT / "tests").glob("*.py"))
    + sorted((ROOT / "benchmarks").glob("*.py")),
    ids=lambda p: str(p.relative_to(ROOT)),
)
def test_no_code_reads_another_modules_private_attributes(path):
    """``module._name`` of a linkopt module (a function, constant or table, not a
    private subpackage) outside that module: the attribute-access form of a private
    import."""
    tree = ast.parse(path.read_text())
    modules = _module_names(tree, path)
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in modules
            and node.attr.startswith("_")
            and not node.attr.startswith("__")
        ):
            assert node.value.id == "linkopt" and _is_module((node.attr,)), (
                f"{path.relative_to(ROOT)}:{node.lineno} reads "
                f"{node.value.id}.{node.attr}"
            )


#: Folders that may draw: the drawing layer and the command line.
DRAWING = {"_draw", "_cli"}


def _absolute_imports(path: Path):
    """The top-level package of every absolute import in ``path``."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield from (alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module.split(".")[0]


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_only_the_drawing_layer_and_the_cli_import_matplotlib(path):
    if _folder(_module_of(path)) in DRAWING:
        return
    drawing = {"matplotlib", "mpl_toolkits"} & set(_absolute_imports(path))
    assert not drawing, f"{path.relative_to(ROOT)} imports {', '.join(drawing)}"


def test_the_matplotlib_check_sees_a_drawing_module():
    """The check above reads the imports that the drawing layer's modules make."""
    assert "matplotlib" in set(_absolute_imports(PACKAGE / "_draw" / "figures.py"))
    assert "matplotlib" in set(
        _absolute_imports(PACKAGE / "_draw" / "arms" / "trace.py")
    )
