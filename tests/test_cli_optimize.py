"""``linkopt optimize``: bad settings exit 2 with one line before any run starts."""

import pytest
from conftest import MECHANISMS

from linkopt._cli.main import main


@pytest.mark.parametrize(
    "flags",
    [
        ["--seed", "-1"],
        ["--particles", "0"],
        ["--tolerance", "0"],
        ["--improvement", "1"],
    ],
)
def test_optimize_command_rejects_bad_settings_with_one_line(flags, tmp_path, capsys):
    assert (
        main(
            [
                "optimize",
                str(MECHANISMS / "five_bar.toml"),
                "--out",
                str(tmp_path / "run"),
                *flags,
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("linkopt: error: --"), err
    assert not (tmp_path / "run").exists()
