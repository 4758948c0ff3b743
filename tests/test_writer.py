"""Designs written back as mechanism files (``linkopt._files.writer``): any name a
TOML file can hold reads back the same, and a file is replaced whole or not at all."""

import os

import pytest
from conftest import MECHANISMS
from hypothesis import given
from hypothesis import strategies as st

import linkopt
from linkopt._files.fields import parse_toml
from linkopt._files.writer import dumps, write_design


@given(
    name=st.text(min_size=1, max_size=30),
    key=st.text(min_size=1, max_size=12),
)
def test_any_string_and_key_round_trips_through_toml(name, key):
    """Regression: a name holding a newline was written raw, breaking the file."""
    data = {"mechanism": {"name": name, key: [1.0, name]}, "items": [{key: name}]}
    assert parse_toml(dumps(data), "x.toml") == data


def test_a_mechanism_named_across_lines_writes_a_file_that_loads(tmp_path):
    text = (MECHANISMS / "five_bar.toml").read_text()
    text = text.replace('name = "five-bar"', 'name = "five\\nbar\\t\\"2\\""', 1)
    mech = linkopt.loads(text, "named.toml")
    assert mech.name == 'five\nbar\t"2"'
    path = write_design(mech, mech.design.p0, 16.0, tmp_path / "out.toml", "a\nb")
    assert linkopt.load(path).name == mech.name


def test_a_failed_write_leaves_the_old_file_whole(five_bar, tmp_path, monkeypatch):
    path = tmp_path / "design.toml"
    path.write_text("# the old file\n")

    def failing(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", failing)
    with pytest.raises(OSError):
        write_design(five_bar, five_bar.design.p0, 16.0, path)
    assert path.read_text() == "# the old file\n"
    assert [p.name for p in tmp_path.iterdir()] == ["design.toml"]


def test_the_written_file_keeps_the_source_files_header(five_bar, tmp_path):
    """Regression (issue 44): ``optimized.toml`` dropped the file's header comments.
    The caller's header comes first, then the source's leading comment block verbatim,
    and the file reads back as the same design; a second write keeps both."""
    source = (MECHANISMS / "five_bar.toml").read_text().splitlines()
    block = source[: source.index("[mechanism]") - 1]
    assert len(block) > 3 and all(line.startswith("#") or not line for line in block)
    path = write_design(
        five_bar, five_bar.design.p0, 16.0, tmp_path / "a.toml", "Optimised."
    )
    lines = path.read_text().splitlines()
    assert lines[:2] == ["# Optimised.", "#"]
    assert lines[2 : 2 + len(block)] == block
    again = write_design(
        linkopt.load(path), five_bar.design.p0, 16.0, tmp_path / "b.toml", "Twice."
    )
    assert again.read_text().splitlines()[2 : 4 + len(block)] == lines[: 2 + len(block)]
    assert linkopt.load(again).design.p0.tolist() == five_bar.design.p0.tolist()


def test_a_mechanism_from_text_has_only_the_callers_header(tmp_path):
    mech = linkopt.loads((MECHANISMS / "five_bar.toml").read_text())
    path = write_design(mech, mech.design.p0, 16.0, tmp_path / "a.toml", "Only.")
    assert path.read_text().startswith("# Only.\n\n[")
