"""What the README and the docs show works: their Python runs, their commands exist.

* Every ```` ```python ```` block of README.md and docs/*.md runs. A page's blocks run in
  order in one namespace, in a fresh working folder, as a reader would paste them; a block
  whose first line is a comment naming a file (``# my_trust.py: ...``) is also saved under
  that name there, so the next blocks can import it. Output samples are fenced as ``text``.
* Every ``swarmloc ...`` command in a code block or an inline code span of README.md and
  docs/ names a command of the CLI's table, and that command's ``--help`` lists every option
  it passes (the argument parser is asked; nothing is run). ``<placeholder>`` in a command's
  place stands for each member of its group.
* The README is a front door of at most ``README_MAX_LINES`` lines, and its leaderboard is
  the one the shipped results give (``swarmloc docs readme``).
"""

from __future__ import annotations

import contextlib
import functools
import io
import re
import shlex
import sys
from pathlib import Path

import pytest

from swarmloc.cli import COMMANDS, main

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
#: Gymnasium's README is about 85 lines; ours adds the leaderboard
README_MAX_LINES = 150
#: pages whose Python blocks run: the README and the hand-written docs (the generated task
#: pages' examples are the environments' doctests, run by tests/test_envs_registry.py)
PYTHON_PAGES = [README, *sorted(DOCS.glob("*.md"))]
#: pages whose commands are checked: the README and every page of docs/, generated ones too
COMMAND_PAGES = [README, *sorted(DOCS.rglob("*.md"))]
FENCE = re.compile(r"^```\s*([\w+-]*)")
PYTHON_FENCES = {"python", "py", "python3"}
#: a block's first line naming the file the reader saves it as
FILE_COMMENT = re.compile(r"^#\s*([A-Za-z_]\w*\.py)\b")


def fenced_blocks(text: str) -> list[tuple[str, str]]:
    """The fenced code blocks of a Markdown text: (language, code), in order."""
    blocks: list[tuple[str, str]] = []
    language, lines = None, []
    for line in text.splitlines():
        match = FENCE.match(line)
        if match and language is None:
            language, lines = match.group(1).lower(), []
        elif line.startswith("```") and language is not None:
            blocks.append((language, "\n".join(lines) + "\n"))
            language = None
        elif language is not None:
            lines.append(line)
    return blocks


def python_blocks(page: Path) -> list[str]:
    return [code for language, code in fenced_blocks(page.read_text(encoding="utf-8")) if language in PYTHON_FENCES]


def _name(page: Path) -> str:
    return str(page.relative_to(ROOT))


@pytest.mark.parametrize("page", [p for p in PYTHON_PAGES if python_blocks(p)], ids=_name)
def test_python_blocks_run(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    before = set(sys.modules)
    namespace: dict = {"__name__": "__main__"}
    try:
        for number, code in enumerate(python_blocks(page), 1):
            saved_as = FILE_COMMENT.match(code)
            if saved_as:
                (tmp_path / saved_as.group(1)).write_text(code, encoding="utf-8")
            try:
                exec(compile(code, f"{_name(page)} block {number}", "exec"), namespace)  # noqa: S102 - the test itself
            except Exception as err:
                raise AssertionError(f"{_name(page)}: Python block {number} fails:\n{code}") from err
    finally:
        for name in set(sys.modules) - before:  # the page's own modules (my_trust, …), not the library's
            file = getattr(sys.modules[name], "__file__", None) or ""
            if file.startswith(str(tmp_path)):
                del sys.modules[name]


def test_the_pages_show_python() -> None:
    assert len(python_blocks(README)) >= 3
    assert sum(len(python_blocks(p)) for p in PYTHON_PAGES) >= 8


# -- commands ----------------------------------------------------------------------------


#: fences whose lines are commands a reader types (``text`` holds output samples, which are not)
SHELL_FENCES = {"", "bash", "sh", "shell", "console"}


def shown_commands(text: str) -> list[str]:
    """The ``swarmloc`` command lines of a Markdown text (shell blocks, with their ``\\``
    continuations and ``$`` prompts, and inline code spans), comments dropped."""
    commands: list[str] = []
    language: str | None = None
    pending = ""
    for line in text.splitlines():
        fence = FENCE.match(line)
        if fence:
            language = fence.group(1).lower() if language is None else None
            continue
        if language in SHELL_FENCES:
            line = pending + line.strip().removeprefix("$ ")
            pending = ""
            if line.endswith("\\"):
                pending = line[:-1] + " "
                continue
            if line.startswith("swarmloc "):
                commands.append(line)
        elif language is None:
            commands += [span for span in re.findall(r"`([^`]+)`", line) if span.startswith("swarmloc ")]
    return [_without_comment(command) for command in commands]


def _without_comment(command: str) -> str:
    lexer = shlex.shlex(command, posix=True, punctuation_chars=False)
    lexer.whitespace_split = True
    lexer.commenters = "#"
    return " ".join(shlex.quote(token) for token in lexer)


def command_paths(tokens: list[str]) -> list[tuple[str, ...]]:
    """The subcommand words of ``swarmloc ...`` (``[("leaderboard", "show")]``); a ``<placeholder>``
    in a group's place gives one path per member of the group."""
    paths: list[tuple[str, ...]] = [()]
    table: object = COMMANDS
    for token in tokens[1:]:
        if not isinstance(table, dict):
            break
        if token.startswith("<") and token.endswith(">"):
            return [(*path, member) for path in paths for member in table]
        if token not in table:
            break
        paths = [(*path, token) for path in paths]
        table = table[token]
    return paths


@functools.cache
def help_text(path: tuple[str, ...]) -> str:
    """``swarmloc <path> --help``, as printed."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as exit_info:
        main([*path, "--help"])
    assert exit_info.value.code == 0, f"swarmloc {' '.join(path)} --help exited with {exit_info.value.code}"
    return out.getvalue()


SHOWN = sorted({(_name(page), line) for page in COMMAND_PAGES
                for line in shown_commands(page.read_text(encoding="utf-8"))})


def test_the_pages_show_commands() -> None:
    readme = [line for page, line in SHOWN if page == "README.md"]
    assert any(line.startswith("swarmloc evaluate ") for line in readme)
    assert any(line.startswith("swarmloc submit ") for line in readme)
    assert len(SHOWN) >= 60


@pytest.mark.parametrize(("page", "line"), SHOWN, ids=[f"{page}: {line[:60]}" for page, line in SHOWN])
def test_shown_command_and_its_options_exist(page: str, line: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "400")  # option names unwrapped in the help
    tokens = shlex.split(line)
    options = [t.split("=", 1)[0] for t in tokens if t.startswith("--")]
    for path in command_paths(tokens):
        rest = tokens[1 + len(path):]
        assert path or all(t.startswith("-") for t in rest), (
            f"{page}: {line!r}: {tokens[1]!r} is not a swarmloc command (known: {sorted(COMMANDS)})")
        text = help_text(path)
        for option in options:
            known = sorted(set(re.findall(r"(?<![\w-])--[a-z][\w-]*", text)))
            assert option in known, (
                f"{page}: {line!r}: swarmloc {' '.join(path)} has no option {option}; it has {known}")


def test_an_unknown_option_or_command_is_caught() -> None:
    text = help_text(("submit",))
    assert "--db-url" in text and not re.search(r"(?<![\w-])--db(?![\w-])", text)
    assert command_paths(shlex.split("swarmloc reproduce <paper> --out x")) == [
        ("reproduce", member) for member in COMMANDS["reproduce"]]
    assert command_paths(shlex.split("swarmloc evaluat --method x")) == [()]


def test_fences_are_read_as_a_reader_sees_them() -> None:
    text = "```python\nx = 1\n```\n\n```text\nswarmloc nothing\n```\n```bash\nswarmloc tasks  # list\n```\n"
    assert fenced_blocks(text) == [("python", "x = 1\n"), ("text", "swarmloc nothing\n"),
                                   ("bash", "swarmloc tasks  # list\n")]
    assert shown_commands("`swarmloc demo --out d` and\n```bash\nswarmloc evaluate \\\n  --suite s\n```\n"
                          "```text\nswarmloc leaderboard — suite x\n```\n```console\n$ swarmloc tasks\n```") == [
        "swarmloc demo --out d", "swarmloc evaluate --suite s", "swarmloc tasks"]


# -- the README ----------------------------------------------------------------------------


def test_the_readme_is_a_front_door() -> None:
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= README_MAX_LINES, f"README.md has {len(text.splitlines())} lines"
    for shown in ("make demo", "make test", "torch==2.13.0", 'gym.make("swarmloc/Scale8-v2")', "swarmloc submit",
                  "docs/index.md"):
        assert shown in text, f"README.md does not show {shown!r}"


def test_the_readme_leaderboard_is_the_shipped_one() -> None:
    from swarmloc.cli.docs_readme import leaderboard_block, with_leaderboard

    text = README.read_text(encoding="utf-8")
    block = leaderboard_block()
    assert "mappo-set-gru" in block and "uniform" in block
    assert with_leaderboard(text, block) == text, (
        "README.md's leaderboard differs from the shipped results in bench/results/standard-v1/; "
        "run `swarmloc docs readme` (or `make docs`)")
