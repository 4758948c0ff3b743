"""mkdocs hooks: the parts of the site generated at build time.

* ``<!-- cli-reference -->`` (reference/cli.md) becomes the ``--help`` text of
  ``linkopt`` and of every sub-command, printed by the command line's own ``main``
  (``linkopt._cli.main``) in this process, so the page cannot drift from the parser;
* ``<!-- performance-results -->`` (performance.md) becomes the figures in
  ``benchmarks/results/*.json``, and for each benchmark script without a results file,
  the command that makes one;
* reference/api.md must name every public name of ``linkopt`` (``linkopt.__all__``) in
  a ``::: linkopt.NAME`` block, and nothing else, and have a ``::: linkopt.MODULE``
  block for every public namespace (``linkopt.arms.dh``): the build fails otherwise;
* the images under ``figures/`` join the site, so pages link ``figures/NAME.png`` as
  the README does;
* the reStructuredText roles of the docstrings (``:func:`x```) are shown as plain code.
"""

from __future__ import annotations

import ast
import contextlib
import importlib
import io
import json
import os
import re
import statistics
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
#: Width of the generated ``--help`` text (argparse reads ``COLUMNS``).
HELP_COLUMNS = 88


# --- figures ------------------------------------------------------------------------


def on_files(files, config):
    for path in sorted((ROOT / "figures").glob("*")):
        if path.suffix.lower() in (".png", ".gif", ".jpg", ".svg"):
            files.append(
                File(
                    f"figures/{path.name}",
                    str(ROOT),
                    config["site_dir"],
                    config["use_directory_urls"],
                )
            )
    return files


# --- command line -------------------------------------------------------------------


def help_text(argv: list[str]) -> str:
    """What ``linkopt ARGV --help`` prints."""
    from linkopt._cli.main import main

    out = io.StringIO()
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(HELP_COLUMNS)
    try:
        with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
            main([*argv, "--help"])
    finally:
        if previous is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = previous
    text = out.getvalue()
    if not text.startswith("usage:"):
        raise PluginError(f"linkopt {' '.join(argv)} --help printed no usage text")
    return text


def subcommands(text: str) -> list[str]:
    """The sub-commands a ``--help`` text lists (``{a,b,c}`` under positional
    arguments), in the parser's order."""
    found = re.search(r"^positional arguments:\n\s+\{([\w,-]+)\}", text, re.M)
    return found.group(1).split(",") if found else []


def cli_reference() -> str:
    """Markdown: one section per command, its ``--help`` text verbatim."""
    parts = []

    def visit(argv: list[str], level: int) -> None:
        text = help_text(argv)
        title = " ".join(["linkopt", *argv])
        parts.append(f"{'#' * level} `{title}`\n\n```text\n{text.rstrip()}\n```\n")
        for name in subcommands(text):
            visit([*argv, name], min(level + 1, 4) if argv else 2)

    visit([], 2)
    return "\n".join(parts)


# --- performance --------------------------------------------------------------------


def _number(value) -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    return f"{value:.4g}"


def _cell(value) -> str:
    """A table cell: numbers to 4 digits; a list of numbers as its median and how many
    runs it has."""
    if (
        isinstance(value, list)
        and value
        and all(isinstance(v, (int, float)) for v in value)
    ):
        if len(value) == 1:
            return _number(value[0])
        return f"{_number(statistics.median(value))} (median of {len(value)})"
    if isinstance(value, dict):
        return ", ".join(f"{k} {_cell(v)}" for k, v in value.items())
    if value is None:
        return ""
    return _number(value).replace("|", "\\|")


def _table(rows: list[dict]) -> str:
    columns: list[str] = []
    for row in rows:
        columns += [key for key in row if key not in columns]
    lines = [
        "| " + " | ".join(columns) + " |",
        "|" + "---|" * len(columns),
    ]
    lines += [
        "| " + " | ".join(_cell(row.get(c)) for c in columns) + " |" for row in rows
    ]
    return "\n".join(lines)


def _result_section(path: Path) -> str:
    data = json.loads(path.read_text())
    lines = [f"### `{path.stem}`\n"]
    if not isinstance(data, dict):
        data = {"results": data}
    head = [f"on {data['date']}"] if "date" in data else []
    if "commit" in data:
        head.append(f"at commit {data['commit']}")
    if isinstance(data.get("machine"), dict):
        head.append("machine: " + _cell(data["machine"]))
    if head:
        lines.append("Measured " + ", ".join(head) + ".\n")
    items: list[str] = []  # consecutive single values, shown as one list
    for key, value in data.items():
        if key in ("date", "commit", "machine"):
            continue
        if (
            isinstance(value, list)
            and value
            and all(isinstance(v, dict) for v in value)
        ):
            table = _table(value)
        elif isinstance(value, dict):
            table = _table([{"": k, "value": v} for k, v in value.items()])
        else:
            items.append(f"- {key}: {_cell(value)}")
            continue
        if items:
            lines.append("\n".join(items) + "\n")
            items = []
        lines.append(f"{key}:\n\n{table}\n")
    if items:
        lines.append("\n".join(items) + "\n")
    return "\n".join(lines)


def _summary(script: Path) -> str:
    doc = ast.get_docstring(ast.parse(script.read_text())) or ""
    return " ".join(doc.split("\n\n")[0].split())


def performance_results() -> str:
    """Markdown: each benchmark script, its current results file
    (``benchmarks/results/<script>.json``) as tables, or the command that makes one."""
    scripts = sorted((ROOT / "benchmarks").glob("bench_*.py"))
    parts = []
    for script in scripts:
        parts.append(f"## `{script.name}`\n\n{_summary(script)}\n")
        result = RESULTS / f"{script.stem}.json"
        if result.is_file():
            parts.append(_result_section(result))
        else:
            parts.append(
                "No results file yet. Run `.venv/bin/python benchmarks/"
                f"{script.name}` (an idle machine gives figures worth keeping).\n"
            )
    others = sorted(
        p.name
        for p in RESULTS.glob("*.json")
        if not (ROOT / "benchmarks" / f"{p.stem}.py").is_file()
    )
    if others:
        parts.append(
            "## Other results files\n\nKept in `benchmarks/results/` for comparison "
            "and not shown here: " + ", ".join(f"`{name}`" for name in others) + ".\n"
        )
    return "\n".join(parts)


# --- API reference ------------------------------------------------------------------


def public_modules() -> set[str]:
    """linkopt's public namespaces, as ``arms.dh``: its modules and packages with no
    part of their name starting with ``_`` (read off the files, importing nothing)."""
    root = ROOT / "linkopt"
    modules = set()
    for path in root.rglob("*.py"):
        parts = path.relative_to(root).with_suffix("").parts
        parts = parts[:-1] if parts[-1] == "__init__" else parts
        if parts and not any(part.startswith("_") for part in parts):
            modules.add(".".join(parts))
    return modules


def check_api(markdown: str) -> None:
    """Every public name of linkopt and of its namespaces is documented once on the
    API page, and only those; every public namespace has its block."""
    import linkopt

    blocks = re.findall(r"^::: linkopt\.([\w.]+)\s*$", markdown, re.M)
    modules = public_modules()
    listed = [name for name in blocks if name not in modules]
    public = set(linkopt.__all__) | {
        f"{module}.{name}"
        for module in modules
        for name in importlib.import_module(f"linkopt.{module}").__all__
        if f"{module}.{name}" not in modules
    }
    missing = sorted(public - set(listed))
    unknown = sorted(set(listed) - public)
    twice = sorted({name for name in blocks if blocks.count(name) > 1})
    problems = []
    if missing:
        problems.append(f"public names missing: {', '.join(missing)}")
    if unknown:
        problems.append(f"not public names of linkopt: {', '.join(unknown)}")
    if twice:
        problems.append(f"listed twice: {', '.join(twice)}")
    if modules - set(blocks):
        problems.append(
            f"namespaces missing: {', '.join(sorted(modules - set(blocks)))}"
        )
    if problems:
        raise PluginError("reference/api.md: " + "; ".join(problems))


# --- page hooks ---------------------------------------------------------------------


def on_page_markdown(markdown, page, config, files):
    if "<!-- cli-reference -->" in markdown:
        markdown = markdown.replace("<!-- cli-reference -->", cli_reference())
    if "<!-- performance-results -->" in markdown:
        markdown = markdown.replace(
            "<!-- performance-results -->", performance_results()
        )
    if page.file.src_uri == "reference/api.md":
        check_api(markdown)
    return markdown


_ROLE = re.compile(
    r":(?:py:)?(?:func|class|mod|meth|data|attr|exc|obj|const):<code>(~?)([^<]*)</code>"
)


def _plain(match: re.Match) -> str:
    name = match.group(2)
    name = name.rsplit(".", 1)[-1] if match.group(1) else name.lstrip(".")
    return f"<code>{name}</code>"


def on_page_content(html, page, config, files):
    return _ROLE.sub(_plain, html)
