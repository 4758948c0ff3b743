"""Designs written back as mechanism files (``linkopt._files.writer``): any name a
TOML file can hold reads back the same, and a file is replaced whole or not at all."""

import os

import pytest
from conftest import MECHANISMS
from hypothesis import given
from hypothesis import strategies as st

import linkopt
from linkopt._engine.fields import parse_toml
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
