"""``--json [PATH]`` and ``--csv [PATH]`` mean the same on every command that has them: no value or
``-`` is standard output (data only), a PATH ending in ``.json`` / ``.csv`` is a file, any other
word after the option stays a positional argument (``reproduce --json 4.2`` is table 4.2), and a
value given with ``=`` that is neither is refused naming the option.

The parsers are checked without running the commands (fast); ``ccjax methods`` runs for real.
"""

from __future__ import annotations

import json

import pytest

from ccjax import cli
from ccjax.cli.common import CommandParser

# Each command with a data option: the smallest arguments its parser accepts, and the positional
# (its name and the words given) that a word after the option must stay.
COMMANDS = {
    "estimate": (["a.png"], "images", ["a.png"]),
    "compare": ([], None, None),
    "reproduce": (["4.2"], "table", "4.2"),
    "calibrate": (["data.csv"], "file", "data.csv"),
    "indexing": ([], None, None),
    "evaluate": (["folder", "--methods", "GW"], "directories", ["folder"]),
    "sharpen": ([], None, None),
    "methods": ([], None, None),
}


def _parse(command: str, *words: str):
    positionals = COMMANDS[command][0]
    return cli.build_parser().parse_args([command, *words, *positionals])


def _commands() -> dict:
    """Every command's parser, built as :func:`ccjax.cli.build_parser` builds them."""
    sub = CommandParser(prog="ccjax").add_subparsers(dest="command")
    for group in cli.groups():
        for add in group.COMMANDS:
            add(sub)
    return sub.choices


def _options_of(command: str) -> list[str]:
    return list(_commands()[command].data_options)


def test_every_command_with_a_data_option_is_listed_here():
    with_data = {name for name, parser in _commands().items() if parser.data_options}
    assert with_data == set(COMMANDS), "add the command to COMMANDS"


@pytest.mark.parametrize("command", COMMANDS)
def test_no_value_and_dash_mean_standard_output_and_a_path_is_a_file(command):
    for option in _options_of(command):
        name = option[2:]
        suffix = "." + name
        assert getattr(_parse(command, option), name) == "-"
        assert getattr(_parse(command, option, "-"), name) == "-"
        assert getattr(_parse(command, option, f"out{suffix}"), name) == f"out{suffix}"
        assert getattr(_parse(command, f"{option}=sub/OUT{suffix.upper()}"), name) == f"sub/OUT{suffix.upper()}"
        assert getattr(_parse(command), name) is None


@pytest.mark.parametrize("command", COMMANDS)
def test_a_value_with_another_suffix_is_refused_naming_the_option(command, capsys):
    for option in _options_of(command):
        with pytest.raises(SystemExit) as exit:
            _parse(command, f"{option}=out.txt")
        assert exit.value.code == 2
        err = capsys.readouterr().err
        assert f"argument {option}: expected '-' (standard output) or a file name ending in .{option[2:]}" in err


@pytest.mark.parametrize("command", [c for c, (_, positional, _) in COMMANDS.items() if positional])
def test_a_word_after_the_option_stays_the_positional_argument(command):
    words, positional, expected = COMMANDS[command]
    for option in _options_of(command):
        args = cli.build_parser().parse_args([command, option, *words])
        assert getattr(args, option[2:]) == "-"
        assert getattr(args, positional) == expected


def test_reproduce_json_4_2_is_table_4_2_as_json():
    args = cli.build_parser().parse_args(["reproduce", "--json", "4.2"])
    assert (args.table, args.json) == ("4.2", "-")


@pytest.mark.parametrize("command", [c for c, (_, positional, _) in COMMANDS.items() if not positional])
def test_a_stray_word_after_the_option_of_a_command_without_positionals_names_the_option(command, capsys):
    for option in _options_of(command):
        with pytest.raises(SystemExit):
            cli.build_parser().parse_args([command, option, "out.txt"])
        assert f"{option}: 'out.txt' is neither '-' nor a file name ending in .{option[2:]}" in capsys.readouterr().err


def test_methods_json_writes_only_the_data_to_standard_output_or_a_file(tmp_path, capsys):
    assert cli.main(["methods", "--json"]) == 0
    captured = capsys.readouterr()
    listed = json.loads(captured.out)  # standard output holds the data alone
    assert listed and "GW" in captured.err  # the table went to standard error
    path = tmp_path / "methods.json"
    assert cli.main(["methods", "--json", str(path)]) == 0
    assert json.loads(path.read_text()) == listed
    assert "GW" in capsys.readouterr().out  # with a file, the table is on standard output
    assert cli.main(["methods", "--json", str(path)]) == 2  # the output rule: no overwrite without --overwrite
    assert "--json" in capsys.readouterr().err
    assert cli.main(["methods", "--json", str(path), "--overwrite"]) == 0
