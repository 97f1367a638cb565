"""`couplekit --help` and each subcommand's help: plain text (no reStructuredText backticks), examples that name
files that exist, and the exit codes the command gives."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from couplekit.cli import build_parser, main
from couplekit.cli_help import EXIT_CODES

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ["", "info", "validate", "run", "sweep", "schema", "plot", "compare", "bench"]


def _help(command: str, capsys) -> str:
    with pytest.raises(SystemExit) as done:
        main([command, "--help"] if command else ["--help"])
    assert done.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c or "couplekit")
def test_help_is_plain_text_with_examples_and_exit_codes(command, capsys):
    text = _help(command, capsys)
    assert "`" not in text, "help shows reStructuredText markup"
    assert "examples:" in text and "exit codes:" in text
    table = text.split("exit codes:", 1)[1]
    for code, meaning in EXIT_CODES[command].items():
        assert re.search(rf"^  {code}\s+{re.escape(meaning[:30])}", table, re.M), f"exit {code} is not listed"
    for path in re.findall(r"(?:examples|benchmarks)/[\w/.-]+\.toml", text):  # the examples run as written
        assert (ROOT / path).is_file(), f"the help names {path}, which does not exist"


def test_every_subcommand_has_help_texts():
    parser = build_parser()
    (sub,) = [a for a in parser._actions if a.dest == "command"]
    assert set(sub.choices) == set(COMMANDS[1:]), "a new subcommand needs its texts in couplekit/cli_help.py"


def test_top_level_lists_the_codes_of_every_subcommand():
    every = {code for table in EXIT_CODES.values() for code in table}
    assert every == set(EXIT_CODES[""])
