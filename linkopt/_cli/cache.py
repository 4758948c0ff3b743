"""``linkopt cache info | clear``: the on-disk caches of compiled executables and
traced programs (:mod:`linkopt._cache`), and whether the compiled kernels are in use
(:mod:`linkopt._kernels`)."""

from __future__ import annotations

import json

from .. import _cache


def _megabytes(count: int) -> str:
    return f"{count / 2**20:.1f} MB"


def _version(pair) -> str:
    return "unknown" if pair is None else ".".join(map(str, pair))


def kernels_line(kernels: dict) -> str:
    """Which path linkopt computes with, and why (:func:`linkopt._kernels.info`)."""
    if kernels["available"]:
        line = f"compiled kernels: in use (version {kernels['version']}"
    else:
        line = f"compiled kernels: not in use, plain JAX ({kernels['reason']}"
    if kernels["extension_version"] is not None:
        line += (
            f"; built against jaxlib {kernels['built_jaxlib'] or 'unknown'}, XLA FFI "
            f"API {_version(kernels['ffi_api_version'])}"
        )
    line += (
        f"; running jaxlib {kernels['running_jaxlib'] or 'none'}, XLA FFI API "
        f"{_version(kernels['running_ffi_api_version'])})"
    )
    if kernels["stale"]:
        line += "; rebuild them (pip install) after editing dense.cc"
    return line


def run_info(args) -> int:
    from .. import _kernels
    from .._engine import dense  # noqa: F401  (registers the kernels, or refuses them)

    payload = _cache.info()
    payload["kernels"] = _kernels.info()
    if args.json:
        print(json.dumps(payload, indent=2))
        return 0
    print(f"cache directory: {payload['directory']}")
    for kind, row in payload["kinds"].items():
        print(
            f"  {kind:<12} {row['entries']:>6} entries  {_megabytes(row['bytes']):>10}"
            f"  of at most {_megabytes(row['limit_bytes'])}  ({row['folder']})"
        )
    print(kernels_line(payload["kernels"]))
    if not payload["bounded_executables"]:
        print(
            "  executables are not bounded here: JAX's eviction needs the filelock "
            "package (pip install filelock)"
        )
    return 0


def run_clear(args) -> int:
    removed = _cache.clear()
    if args.json:
        print(json.dumps({"removed": removed}, indent=2))
    else:
        print(
            "removed "
            + ", ".join(f"{count} {kind}" for kind, count in removed.items())
            + f" from {_cache.cache_directory()}"
        )
    return 0


def register(subparsers) -> None:
    """Add ``cache info`` and ``cache clear`` to the ``linkopt`` sub-commands."""
    cmd = subparsers.add_parser(
        "cache",
        help="size of linkopt's compilation caches, or clear them",
        description=(
            "Compiled executables and traced programs are kept under "
            "$LINKOPT_CACHE_DIR (default ~/.cache/linkopt/jax), at most "
            "$LINKOPT_CACHE_SIZE_MB megabytes in all (default "
            f"{_cache.DEFAULT_MB}), least recently used removed first."
        ),
    )
    sub = cmd.add_subparsers(dest="cache_command", required=True)
    info = sub.add_parser("info", help="entries, size and limit of each cache")
    info.add_argument("--json", action="store_true", help="machine-readable output")
    info.set_defaults(run=run_info)
    clear = sub.add_parser("clear", help="remove every cached entry")
    clear.add_argument("--json", action="store_true", help="machine-readable output")
    clear.set_defaults(run=run_clear)
