"""JAX configured for linkopt before it computes, without importing JAX for the
command line's help and its input errors.

Importing :mod:`linkopt` does not import JAX: ``linkopt --help``, a usage error and a
file that cannot be read answer without waiting for it. :func:`configure_before_jax`
puts a finder on ``sys.meta_path`` that imports :mod:`linkopt._config` (float64 and the
compilation cache) before the first linkopt module outside :data:`JAX_FREE` and the
command line; every module that computes with JAX is such a module.
``tests/test_cli_startup.py`` checks that the listed modules import no JAX and that a
module that does finds float64 on.

The public namespaces (:mod:`linkopt.arms.codesign`, :mod:`linkopt.arms.dh`,
:mod:`linkopt.arms.trace`, :mod:`linkopt.export`) are JAX-free too: each gets its
``__getattr__`` and ``__dir__`` from :func:`namespace`, and a name's first use imports
it as :mod:`linkopt`'s top-level name, which configures JAX first.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterable, Mapping

PACKAGE = __name__.rpartition(".")[0]
#: The modules that never import JAX: what the command line checks before any
#: computation (it imports the rest inside its handlers, ``linkopt._cli``).
JAX_FREE = frozenset(
    f"{PACKAGE}.{name}"
    for name in (
        "__main__",
        "_cache",
        "_config",
        "_errors",
        "_folders",
        "_imports",
        "_machine",
        "arms",
        "arms.codesign",
        "arms.dh",
        "arms.trace",
        "export",
        "synthesis",
        "_arms",
        "_arms.checks",
        "_arms.dh",
        "_arms.dh.points",
        "_arms.dh.settings",
        "_arms.limits",
        "_arms.trace",
        "_arms.trace.settings",
        "_arms.trace.task",
        "_design",
        "_design.ahead",
        "_design.settings",
        "_draw",
        "_draw.arms",
        "_engine",
        "_engine.assembly",
        "_engine.assembly.axes",
        "_engine.assembly.lines",
        "_engine.assembly.problem",
        "_engine.assembly.refusal",
        "_engine.assembly.solve",
        "_engine.assembly.write",
        "_engine.attachment",
        "_engine.design_angles",
        "_engine.design_kinds",
        "_engine.design_space",
        "_engine.fields",
        "_engine.links",
        "_engine.model",
        "_engine.rotations",
        "_engine.symmetry",
        "_engine.welding",
        "_export",
        "_files",
        "_files.bounds",
        "_files.loader",
        "_files.outputs",
        "_files.points",
        "_files.settings",
        "_files.synthesis",
        "_files.topology",
        "_kernels",
        "_kernels._dense",
    )
)


class ConfigFirst:
    """A finder that finds nothing: it imports :mod:`linkopt._config` before the first
    linkopt module that is not in :data:`JAX_FREE` or the command line."""

    @staticmethod
    def find_spec(name, path=None, target=None):
        if (
            name.startswith(f"{PACKAGE}.")
            and name not in JAX_FREE
            and not name.startswith(f"{PACKAGE}._cli")
            and f"{PACKAGE}._config" not in sys.modules
        ):
            importlib.import_module(f"{PACKAGE}._config")
        return None


def configure_before_jax() -> None:
    """Install :class:`ConfigFirst` (once); configure at once when JAX is already
    imported (it then costs nothing)."""
    if not any(isinstance(finder, ConfigFirst) for finder in sys.meta_path):
        sys.meta_path.insert(0, ConfigFirst())
    if "jax" in sys.modules:
        importlib.import_module(f"{PACKAGE}._config")


def namespace(
    module: str, names: Mapping[str, str], submodules: Iterable[str] = ()
) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """The ``__getattr__`` and ``__dir__`` (PEP 562) of the public namespace
    ``module``: its name ``name`` is the top-level name ``names[name]`` of
    :mod:`linkopt`, the same object, looked up on first use (so it configures JAX as
    the top-level name does); each of ``submodules`` is imported on first use."""
    submodules = tuple(submodules)

    def __getattr__(name: str):
        if name in submodules:
            value = importlib.import_module(f"{module}.{name}")
        elif name in names:
            value = getattr(importlib.import_module(PACKAGE), names[name])
        else:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        setattr(sys.modules[module], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[module])) | set(names) | set(submodules))

    return __getattr__, __dir__
