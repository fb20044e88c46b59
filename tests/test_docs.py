"""The README and docs/ stay true: every link to a file of the project leads somewhere, and every
``illusion-studio …`` command in their code blocks names subcommands and options the CLI has."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import click
import pytest

from webapp.cli import main

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
CODE = re.compile(r"^```(?:sh|bash)?\n(.*?)^```", re.S | re.M)


def commands(text: str) -> list[list[str]]:
    """The ``illusion-studio`` invocations in ``text``'s shell code blocks, as argument lists."""
    found = []
    for block in CODE.findall(text):
        for line in block.splitlines():
            for part in re.split(r"[;&]", line.split(" #")[0]):
                words = shlex.split(part, comments=True) if part.strip() else []
                if words[:1] == ["illusion-studio"]:
                    found.append(words[1:])
    return found


def check(args: list[str]) -> None:
    """Walk ``args`` down the CLI: each subcommand exists (``a|b`` alternatives each), each ``--option``
    is one its command takes."""
    command: click.Command = main
    context = click.Context(main)
    for word in args:
        if word.startswith("-"):
            name = word.split("=")[0]
            options = {o for p in command.params for o in (*p.opts, *p.secondary_opts)} | {"-h", "--help"}
            assert name in options, f"{' '.join(args)}: {command.name} takes no {name}"
        elif isinstance(command, click.Group):
            choices = word.split("|")
            found = [command.get_command(context, c) for c in choices]
            if all(found):
                command = found[0]  # type: ignore[assignment]
            else:
                assert not any(found), f"{' '.join(args)}: {word} is partly not a command"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_link_leads_to_a_file(page: Path) -> None:
    for target in LINK.findall(page.read_text()):
        if "://" in target:
            continue
        assert (page.parent / target).exists(), f"{page.name} links to {target}, which does not exist"


@pytest.mark.parametrize("page", [ROOT / "README.md", ROOT / "docs" / "cli.md"], ids=["README", "cli"])
def test_every_command_shown_is_one_the_cli_takes(page: Path) -> None:
    shown = commands(page.read_text())
    assert shown, f"{page.name} shows no illusion-studio command"
    for args in shown:
        check(args)


def test_the_readme_is_short_and_indexes_every_doc() -> None:
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 200
    for doc in (ROOT / "docs").glob("*.md"):
        assert f"docs/{doc.name}" in readme, f"the README's index misses docs/{doc.name}"


def test_a_wrong_command_is_caught() -> None:
    with pytest.raises(AssertionError):
        check(["users", "create", "--no-such-option"])
    with pytest.raises(AssertionError):
        check(["export", "--formatt", "native"])
