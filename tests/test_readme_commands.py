"""Every ``swarmloc`` command the README shows exists, with every option it uses.

Commands are read from the README's code blocks (lines starting with ``swarmloc``, with
their ``\\`` continuations) and from inline code spans (`` `swarmloc ...` ``); each one's
command path is looked up in the CLI's table and its ``--help`` must list every option
the README passes.
"""

from __future__ import annotations

import contextlib
import functools
import io
import re
import shlex
from pathlib import Path

import pytest

from swarmloc.bench.cli import COMMANDS, main

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_commands(text: str) -> list[str]:
    """The ``swarmloc`` command lines of a Markdown text, comments dropped."""
    commands: list[str] = []
    in_block = False
    pending = ""
    for line in text.splitlines():
        if line.startswith("```"):
            in_block = not in_block
            continue
        if in_block:
            line = pending + line.strip()
            pending = ""
            if line.endswith("\\"):
                pending = line[:-1] + " "
                continue
            if line.startswith("swarmloc "):
                commands.append(line)
        else:
            commands += [span for span in re.findall(r"`([^`]+)`", line) if span.startswith("swarmloc ")]
    return [_without_comment(command) for command in commands]


def _without_comment(command: str) -> str:
    lexer = shlex.shlex(command, posix=True, punctuation_chars=False)
    lexer.whitespace_split = True
    lexer.commenters = "#"
    return " ".join(shlex.quote(token) for token in lexer)


def command_path(tokens: list[str]) -> tuple[str, ...]:
    """The subcommand words of ``swarmloc ...`` (``("leaderboard", "show")``, ``("submit",)``)."""
    path: list[str] = []
    table: object = COMMANDS
    for token in tokens[1:]:
        if not isinstance(table, dict) or token not in table:
            break
        path.append(token)
        table = table[token]
    return tuple(path)


@functools.cache
def help_text(path: tuple[str, ...]) -> str:
    """``swarmloc <path> --help``, as printed."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as exit_info:
        main([*path, "--help"])
    assert exit_info.value.code == 0, f"swarmloc {' '.join(path)} --help exited with {exit_info.value.code}"
    return out.getvalue()


COMMAND_LINES = readme_commands(README.read_text(encoding="utf-8"))


def test_the_readme_shows_commands() -> None:
    assert len(COMMAND_LINES) >= 10
    assert any(line.startswith("swarmloc submit ") for line in COMMAND_LINES)


@pytest.mark.parametrize("line", COMMAND_LINES)
def test_readme_command_and_its_options_exist(line: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "400")  # option names unwrapped in the help
    tokens = shlex.split(line)
    path = command_path(tokens)
    rest = tokens[1 + len(path):]
    assert path or all(t.startswith("-") for t in rest), (
        f"{line!r}: {tokens[1]!r} is not a swarmloc command (known: {sorted(COMMANDS)})"
    )
    text = help_text(path)
    for option in (t.split("=", 1)[0] for t in tokens if t.startswith("--")):
        assert re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", text), (
            f"{line!r}: swarmloc {' '.join(path)} has no option {option}; its --help:\n{text}"
        )


def test_an_unknown_option_is_caught() -> None:
    text = help_text(("submit",))
    assert "--db-url" in text and not re.search(r"(?<![\w-])--db(?![\w-])", text)
