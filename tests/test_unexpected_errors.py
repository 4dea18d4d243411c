"""An error ccjax did not expect (a bug, not a bad input) ends the command with one line: the usual
``ccjax CMD: error:`` prefix, the error's type, the place in ccjax it came from, exit status 1;
``CCJAX_TRACEBACK=1`` shows the traceback instead."""

from __future__ import annotations

import re

import pytest

import ccjax.cli as cli


def _break_the_world_command(monkeypatch):
    def broken(args):
        return {}["missing key"]  # a KeyError, as a bug would raise it

    parser = cli.build_parser
    monkeypatch.setattr(cli, "build_parser", lambda: _with_func(parser(), broken), raising=True)


def _with_func(parser, func):
    parser.set_defaults(func=func)
    for action in parser._subparsers._group_actions:  # every subcommand runs the broken function
        for sub in action.choices.values():
            sub.set_defaults(func=func)
    return parser


def test_an_unexpected_error_is_one_line_with_its_type_and_place(monkeypatch, capsys):
    monkeypatch.delenv(cli.TRACEBACK_VARIABLE, raising=False)
    _break_the_world_command(monkeypatch)
    assert cli.main(["world"]) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    assert re.fullmatch(
        r"ccjax world: error: unexpected KeyError at ccjax/cli/__init__\.py:\d+: 'missing key' "
        r"\(a ccjax bug: please report it; CCJAX_TRACEBACK=1 shows the traceback\)\n",
        err,
    ), err


def test_the_traceback_variable_shows_the_traceback(monkeypatch):
    monkeypatch.setenv(cli.TRACEBACK_VARIABLE, "1")
    _break_the_world_command(monkeypatch)
    with pytest.raises(KeyError, match="missing key"):
        cli.main(["world"])


def test_bad_input_keeps_exit_two_and_the_plain_line(monkeypatch, capsys):
    monkeypatch.delenv(cli.TRACEBACK_VARIABLE, raising=False)
    error = ValueError("--scenes: expected a positive integer, got 0")
    assert cli.unexpected_error_line("compare", KeyError("k")).startswith("ccjax compare: error: unexpected KeyError")

    def bad(args):
        raise error

    monkeypatch.setattr(cli, "build_parser", lambda parser=cli.build_parser: _with_func(parser(), bad))
    assert cli.main(["world"]) == 2
    assert capsys.readouterr().err == "ccjax world: error: --scenes: expected a positive integer, got 0\n"


def test_the_place_is_in_the_installed_package_not_in_a_folder_named_ccjax():
    # A clone named ccjax holds tests and scripts: a frame there is not a place in the package.
    namespace: dict = {}
    exec(compile("def broken():\n    return {}['k']\n", "/elsewhere/ccjax/tests/fake.py", "exec"), namespace)
    try:
        namespace["broken"]()
    except KeyError as error:
        line = cli.unexpected_error_line("world", error)
    assert " at fake.py:2: 'k' " in line and "ccjax/tests" not in line
