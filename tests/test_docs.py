"""The documentation agrees with the code.

* Every key the mechanism-file loader accepts is documented in
  ``docs/reference/mechanism-file.md``, in the section of its table, and every key
  documented there is accepted. The keys are not listed here: they are recorded from
  the loader itself, by watching the field reader (:class:`Reader`) while the shipped
  mechanisms, the test data and the documentation's own files are loaded. A further
  test makes sure that this corpus reaches every place where the loader declares the
  keys of a table, so a new key, or a new table, cannot go unrecorded either.
* The ``[solver]`` and ``[evaluation]`` rows state the defaults the loader applies and
  the ranges it enforces (read off its error messages).
* Every fenced code block of ``README.md`` and ``docs/tutorial.md`` runs, in order, in a
  temporary folder holding a copy of ``mechanisms/``:

  - ``bash`` blocks: each line is a ``linkopt`` command, run as
    ``python -m linkopt ...`` with this interpreter; it must exit 0, or with N where
    the line ends in the comment ``# exit status N``;
  - ``python`` blocks are executed;
  - a block with a title (``toml title="NAME"``) is a file: its text is appended to
    ``NAME`` (the tutorial writes its mechanism file step by step);
  - ``text`` blocks without a title are program output or drawings and are not run;
  - a block right after the line ``<!-- skip-test -->`` is not run (the README's
    set-up, main job and test commands, which CI runs anyway, and ``optimize``).
* ``mkdocs build --strict`` succeeds (skipped when mkdocs is not installed).
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import functools
import importlib.util
import inspect
import io
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

import linkopt
from linkopt._cli.main import main
from linkopt._files.fields import Reader, parse_toml
from linkopt._files.loader import build

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "docs" / "reference" / "mechanism-file.md"
RUN_DOCUMENTS = [ROOT / "README.md", ROOT / "docs" / "tutorial.md"]
SKIP_MARK = "<!-- skip-test -->"
SHELL = {"bash", "sh", "shell"}
#: Files to write may be of these languages; ``text`` without a title is output.
FILE_LANGUAGES = {"toml", "csv", "text"}


# --- fenced code blocks -------------------------------------------------------------


@dataclass(frozen=True)
class Block:
    path: Path
    line: int  # of the opening fence, 1-based
    language: str
    title: str | None
    text: str
    skip: bool

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def code_blocks(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown file (fences at the start of a line)."""
    blocks, lines = [], path.read_text(encoding="utf-8").splitlines()
    k, previous = 0, ""
    while k < len(lines):
        opening = re.match(r"^```(\w*)(.*)$", lines[k])
        if not opening:
            if lines[k].strip():
                previous = lines[k].strip()
            k += 1
            continue
        end = next(i for i in range(k + 1, len(lines)) if lines[i].startswith("```"))
        title = re.search(r'title="([^"]+)"', opening.group(2))
        blocks.append(
            Block(
                path,
                k + 1,
                opening.group(1),
                title.group(1) if title else None,
                "\n".join(lines[k + 1 : end]) + "\n",
                previous == SKIP_MARK,
            )
        )
        previous, k = "", end + 1
    return blocks


def documented_files(path: Path) -> dict[str, str]:
    """The files a page's titled blocks write (blocks of one title appended)."""
    files: dict[str, str] = {}
    for block in code_blocks(path):
        if block.title:
            files[block.title] = files.get(block.title, "") + block.text
    return files


@dataclass(frozen=True)
class Command:
    argv: list[str]
    status: int
    where: str


def shell_commands(block: Block) -> list[Command]:
    """The ``linkopt`` commands of a shell block (continuation lines joined)."""
    joined, pending = [], ""
    for line in block.text.splitlines():
        if line.rstrip().endswith("\\"):
            pending += line.rstrip()[:-1] + " "
            continue
        joined.append(pending + line)
        pending = ""
    commands = []
    for line in joined:
        status = re.search(r"#\s*exit status (\d+)\s*$", line)
        words = shlex.split(line, comments=True)
        if not words:
            continue
        assert words[0] == "linkopt", (
            f"{block.where}: only linkopt commands run in a documentation test, got "
            f"{line.strip()!r}; mark an illustrative block with {SKIP_MARK}"
        )
        commands.append(
            Command(words[1:], int(status.group(1)) if status else 0, block.where)
        )
    return commands


def check_block_kind(block: Block) -> None:
    """A block is a file, a shell or Python block, or output; anything else is a
    mistake in the page."""
    if block.title:
        assert block.language in FILE_LANGUAGES, (
            f"{block.where}: a titled block is a file; expected one of "
            f"{sorted(FILE_LANGUAGES)}, got {block.language!r}"
        )
    elif block.language in SHELL:
        if not block.skip:
            shell_commands(block)
    else:
        assert block.language in ("python", "text") or block.skip, (
            f"{block.where}: a {block.language or 'plain'} block without a title is "
            f"neither run nor written; give it a title, or mark it {SKIP_MARK}"
        )


@pytest.mark.parametrize("path", RUN_DOCUMENTS, ids=lambda p: p.name)
def test_code_blocks_are_of_a_kind_the_tests_run(path):
    blocks = code_blocks(path)
    assert blocks, f"{path.name} has no code blocks"
    for block in blocks:
        check_block_kind(block)
        assert not (block.skip and block.language == "python"), (
            f"{block.where}: Python samples must run"
        )


def run_blocks(path: Path, folder: Path) -> None:
    shutil.copytree(ROOT / "mechanisms", folder / "mechanisms")
    for block in code_blocks(path):
        check_block_kind(block)
        if block.skip:
            continue
        if block.title:
            with open(folder / block.title, "a", encoding="utf-8") as file:
                file.write(block.text)
        elif block.language in SHELL:
            for command in shell_commands(block):
                run_command(command, folder)
        elif block.language == "python":
            code = compile(block.text, block.where, "exec")
            exec(code, {"__name__": "__docs__"})


def run_command(command: Command, folder: Path) -> None:
    """``linkopt ARGS`` as the command line runs it, in this process (in ``folder``,
    the current directory): the blocks' commands then share compiled programs, where a
    process each compiled or loaded them again (``tests/test_cli_startup.py`` runs the
    entry point in fresh processes)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = main(list(command.argv))
        except SystemExit as stop:  # argparse's --help
            status = stop.code
    assert Path.cwd() == folder
    assert status == command.status, (
        f"{command.where}: linkopt {shlex.join(command.argv)} exited "
        f"{status}, expected {command.status}\n{out.getvalue()}\n{err.getvalue()}"
    )


@pytest.mark.slow
@pytest.mark.timeout(1800)
@pytest.mark.parametrize("path", RUN_DOCUMENTS, ids=lambda p: p.name)
def test_code_blocks_run(path, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    run_blocks(path, tmp_path)


# --- what the loader accepts --------------------------------------------------------

#: Reader methods that read one field: ``(data, key, where, ...)``.
FIELD_READERS = (
    "string",
    "boolean",
    "number",
    "positive",
    "positive_integer",
    "vector",
    "point",
    "direction",
    "bounded",
    "integer",
)
READER_FILE = Path(sys.modules[Reader.__module__].__file__).resolve()


def table_of(where: str) -> tuple[str, str] | None:
    """``[name]``/``name[3]``/``name[3].sub[1]`` -> (``[name]`` or ``[[name]]``, the
    key prefix of a nested table, e.g. ``"ties."``); None for anything else."""
    if re.fullmatch(r"\[\w+\]", where):
        return where, ""
    entry = re.fullmatch(r"(\w+)\[\d+\]((?:\.\w+\[\d+\])*)", where)
    if not entry:
        return None
    nested = re.sub(r"\[\d+\]", "", entry.group(2)).lstrip(".")
    return f"[[{entry.group(1)}]]", nested + "." if nested else ""


@dataclass
class Recorded:
    """What the loader's field reader was asked for."""

    keys: dict[str, set[str]] = dataclasses.field(default_factory=dict)
    arrays: set[str] = dataclasses.field(default_factory=set)
    sites: set[tuple[str, int]] = dataclasses.field(default_factory=set)

    def add(self, where: str, names) -> None:
        table = table_of(where) if where else ("", "")
        if table is not None:
            name, prefix = table
            self.keys.setdefault(name, set()).update(prefix + n for n in names)


def _caller() -> tuple[str, int]:
    frame = sys._getframe(2)
    while Path(frame.f_code.co_filename).resolve() == READER_FILE:
        frame = frame.f_back
    return str(Path(frame.f_code.co_filename).resolve()), frame.f_lineno


def _recording(recorded: Recorded, name: str):
    method = getattr(Reader, name)
    signature = inspect.signature(method)

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        recorded.sites.add(_caller())
        given = signature.bind(self, *args, **kwargs).arguments
        if name in ("keys", "table"):
            recorded.add(given["where"], given["allowed"])
        elif name == "top_level":
            recorded.add("", given["allowed"])
        elif name == "entries":
            recorded.arrays.add(given["key"])
            recorded.add("", [given["key"]])
        elif (table_of(given["where"]) or ("", "nested"))[1] == "":
            # a field of a table itself, not of a nested map such as a body's anchors
            recorded.add(given["where"], [given["key"]])
        return method(self, *args, **kwargs)

    return wrapper


def _body_frame_keys() -> tuple[str, ...]:
    """Keys of a body given in its own frame: assembly recognises such a body by them
    and removes them before the loader reads ``[[bodies]]``."""
    from linkopt._files.assembly import BODY_KEYS

    return BODY_KEYS


PROBE_BASE = (ROOT / "mechanisms" / "four_bar.toml").read_text()


def probe(text: str) -> str:
    """The loader's error message for ``four_bar.toml`` plus ``text`` ('' if none)."""
    try:
        build(parse_toml(PROBE_BASE + "\n" + text, "probe.toml"), "probe.toml", False)
    except linkopt.MechanismFileError as err:
        return str(err)
    return ""


def corpus() -> list[tuple[str, str]]:
    """(name, text) of every mechanism file the tests know: the shipped ones, the test
    data and the files the documentation writes."""
    files = [
        (str(p.relative_to(ROOT)), p.read_text())
        for p in sorted(ROOT.glob("mechanisms/*.toml"))
        + sorted(ROOT.glob("tests/data/*.toml"))
    ]
    for page in sorted((ROOT / "docs").rglob("*.md")):
        for name, text in documented_files(page).items():
            if name.endswith(".toml"):
                files.append((f"{page.relative_to(ROOT)}:{name}", text))
    return files


@pytest.fixture(scope="module")
def recorded() -> Recorded:
    out = Recorded()
    with pytest.MonkeyPatch.context() as patch:
        for name in ("keys", "table", "top_level", "entries", *FIELD_READERS):
            patch.setattr(Reader, name, _recording(out, name))
        for name, text in corpus():
            build(parse_toml(text, name), name, check=False)
        # settings tables: an unknown key makes the loader read the table's keys
        for table in ("solver", "evaluation"):
            probe(f"[{table}]\nnot_a_setting = 1\n")
    out.keys.setdefault("[[bodies]]", set()).update(_body_frame_keys())
    return out


def reader_call_sites() -> list[tuple[str, int, int]]:
    """Every place in the package (serial-arm task formats aside) where a table's keys
    are declared: ``rd.keys(...)``, ``rd.table(...)``, ``rd.top_level(...)``."""
    sites = []
    for path in sorted((ROOT / "linkopt").rglob("*.py")):
        if "_arms" in path.parts or path.resolve() == READER_FILE:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if not (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr in ("keys", "table", "top_level")
            ):
                continue
            receiver = node.func.value
            if (isinstance(receiver, ast.Name) and receiver.id == "rd") or (
                isinstance(receiver, ast.Attribute) and receiver.attr == "rd"
            ):
                sites.append((str(path.resolve()), node.lineno, node.end_lineno))
    return sites


def test_the_corpus_reaches_every_table_the_loader_reads(recorded):
    sites = reader_call_sites()
    assert len(sites) > 10, "no reader call sites found: has the field reader moved?"
    missed = [
        f"{Path(path).relative_to(ROOT)}:{first}"
        for path, first, last in sites
        if not any(p == path and first <= line <= last for p, line in recorded.sites)
    ]
    assert not missed, (
        "no mechanism file in mechanisms/, tests/data/ or the docs' titled blocks "
        f"reaches these key declarations, so their keys are not checked: {missed}; "
        "add a documented example that uses them"
    )


# --- what the reference page documents ----------------------------------------------


def _cells(row: str) -> list[str]:
    return [c.strip() for c in re.split(r"(?<!\\)\|", row.strip().strip("|"))]


@functools.cache
def reference_sections() -> dict[str, dict]:
    """``[name]``/``[[name]]`` -> {"rows": {key: {column: cell}}, "text": section}:
    the sections whose heading is a table name, with the rows of their key tables."""
    lines = REFERENCE.read_text(encoding="utf-8").splitlines()
    sections, current, level = {}, None, 0
    header: list[str] = []
    for line in lines:
        heading = re.match(r"^(#+)\s+(.*)$", line)
        if heading and not line.startswith("#!"):
            depth = len(heading.group(1))
            name = re.fullmatch(r"`(\[\[?\w+\]\]?)`", heading.group(2).strip())
            if name:
                current, level = name.group(1), depth
                sections[current] = {"rows": {}, "text": ""}
                continue
            if current and depth <= level:
                current = None
        if current is None:
            continue
        sections[current]["text"] += line + "\n"
        if not line.startswith("|"):
            header = []
            continue
        cells = _cells(line)
        if not header:
            header = [c.lower() for c in cells]
            continue
        key = re.fullmatch(r"`([\w.]+)`", cells[0])
        if key and header[0] == "key":
            sections[current]["rows"][key.group(1)] = dict(zip(header, cells))
    return sections


def test_every_table_the_loader_accepts_has_a_section(recorded):
    sections = reference_sections()
    for name in sorted(recorded.keys[""]):
        heading = f"[[{name}]]" if name in recorded.arrays else f"[{name}]"
        assert heading in sections, (
            f"{REFERENCE.name}: no section '## `{heading}`' for the table {name!r}, "
            "which the loader accepts"
        )


def test_every_key_the_loader_accepts_is_documented(recorded):
    sections = reference_sections()
    missing = {
        table: sorted(keys - set(sections.get(table, {"rows": {}})["rows"]))
        for table, keys in sorted(recorded.keys.items())
        if table
    }
    missing = {table: keys for table, keys in missing.items() if keys}
    assert not missing, (
        f"{REFERENCE.name}: keys the loader accepts without a row in the section of "
        f"their table: {missing}"
    )


def test_every_documented_key_is_accepted(recorded):
    extra = {
        table: sorted(set(section["rows"]) - recorded.keys.get(table, set()))
        for table, section in sorted(reference_sections().items())
    }
    extra = {table: keys for table, keys in extra.items() if keys}
    assert not extra, (
        f"{REFERENCE.name}: documented keys the loader does not accept: {extra}"
    )


def _states(text: str, number: str) -> bool:
    """``number`` appears in ``text`` as a whole number (``1000`` not in ``10000``)."""
    return re.search(rf"(?<![\w.+-]){re.escape(number)}(?![\w.])", text) is not None


def _default_cell(row: dict) -> str:
    return row["default"].replace("`", "").strip()


@pytest.mark.parametrize("table", ["solver", "evaluation"])
def test_settings_defaults_and_ranges_are_documented(table, recorded):
    defaults = dataclasses.asdict(
        getattr(linkopt.load(ROOT / "mechanisms" / "four_bar.toml"), table)
    )
    rows = reference_sections()[f"[{table}]"]["rows"]
    problems = []
    for key in sorted(recorded.keys[f"[{table}]"]):
        row, default = rows[key], defaults[key]
        cell = _default_cell(row)
        if default is None:
            if not cell.startswith("none"):
                problems.append(f"{key}: default {cell!r}, the loader's none")
        else:
            written = tomllib.loads(f"v = {cell}")["v"]
            expected = list(default) if isinstance(default, tuple) else default
            if written != expected:
                problems.append(f"{key}: default {cell}, the loader's {default!r}")
        message = probe(f"[{table}]\n{key} = {10**30}\n")
        bounds = re.search(r"from (\S+) to (\S+), got", message)
        if bounds and not all(_states(row["type"], b) for b in bounds.groups()):
            problems.append(
                f"{key}: the loader's range is {bounds.group(1)} to "
                f"{bounds.group(2)}, the type column says {row['type']!r}"
            )
    assert not problems, f"{REFERENCE.name}: [{table}]: " + "; ".join(problems)


def test_joint_types_and_their_rows_are_documented():
    from linkopt._engine.model import JOINT_ROWS

    text = reference_sections()["[[joints]]"]["text"]
    for kind, rows in JOINT_ROWS.items():
        assert re.search(rf"^\| `{kind}` \| {rows} \|", text, re.M), (
            f"{REFERENCE.name}: joint type {kind!r} ({rows} rows) is not in the "
            "joint-type table"
        )


def test_enumerated_values_are_documented():
    from linkopt._engine.model import COORDINATES, OUTPUT_KINDS
    from linkopt._files.design_kinds import KINDS
    from linkopt._files.outputs import ORIENTATION_ANGLES

    sections = reference_sections()
    for table, values in (
        ("[[outputs]]", list(OUTPUT_KINDS) + list(ORIENTATION_ANGLES)),
        ("[[parameters]]", list(KINDS) + list(COORDINATES)),
    ):
        for value in values:
            assert f"`{value}`" in sections[table]["text"] or (
                f'`"{value}"`' in sections[table]["text"]
            ), f"{REFERENCE.name}: {table} does not mention {value!r}"


@pytest.mark.slow
def test_documented_mechanism_files_load():
    for page in sorted((ROOT / "docs").rglob("*.md")):
        for name, text in documented_files(page).items():
            if name.endswith(".toml"):
                linkopt.loads(text, f"{page.relative_to(ROOT)}:{name}")


# --- the site -----------------------------------------------------------------------


@pytest.mark.slow
def test_mkdocs_build_is_strict_clean(tmp_path):
    for module in ("mkdocs", "material", "mkdocstrings_handlers.python"):
        if importlib.util.find_spec(module.split(".")[0]) is None:
            pytest.skip(f"{module} is not installed (pip install -e '.[docs]')")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict"]
        + ["--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-4000:]
