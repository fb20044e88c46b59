"""The command line as a user types it: real processes, exit codes, one-line errors, nothing written on failure."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import click
import pytest

ROOT = Path(__file__).resolve().parent.parent


def cli(*args: str, stdin: str = "", env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("ILLUSION_STUDIO_")}
    return subprocess.run([sys.executable, "-m", "webapp.cli", *args], input=stdin, capture_output=True,
                          text=True, cwd=ROOT, env={**clean, **(env or {})}, timeout=120)


def one_line_error(result: subprocess.CompletedProcess[str], message: str) -> None:
    assert result.returncode != 0
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.stderr


@pytest.fixture
def ws(tmp_path: Path) -> Path:
    home = tmp_path / "ws"
    result = cli("--data-dir", str(home), "init")
    assert result.returncode == 0, result.stderr
    assert "workspace ready" in result.stdout
    return home


def test_init_creates_a_workspace_and_is_repeatable(ws: Path) -> None:
    assert (ws / "illusion-studio.db").is_file() and (ws / "media").is_dir()
    assert cli("--data-dir", str(ws), "init").returncode == 0


def test_users_and_tokens(ws: Path) -> None:
    d = ("--data-dir", str(ws))
    result = cli(*d, "users", "create", "alice", "--role", "curator", "--password-stdin", stdin="s3cret-pass\n")
    assert result.returncode == 0 and "created curator alice" in result.stdout
    token = cli(*d, "users", "token", "alice").stdout.strip().splitlines()[-1]
    assert token.startswith("ist_") and len(token) > 30
    assert "alice" in cli(*d, "users", "list").stdout
    # the data dir may also come from the environment
    assert "alice" in cli("users", "list", env={"ILLUSION_STUDIO_HOME": str(ws)}).stdout


def test_bad_input_is_one_clear_line_and_writes_nothing(ws: Path, tmp_path: Path) -> None:
    d = ("--data-dir", str(ws))
    assert cli(*d, "users", "create", "bob", "--role", "annotator", "--password-stdin", stdin="long-enough\n").returncode == 0
    before = (ws / "illusion-studio.db").stat().st_size, cli(*d, "users", "list").stdout
    one_line_error(cli(*d, "users", "create", "bob", "--role", "admin", "--password-stdin", stdin="long-enough\n"),
                   "already exists")
    one_line_error(cli(*d, "users", "create", "carol", "--role", "overlord", "--password-stdin", stdin="long-enough\n"),
                   "unknown role 'overlord'")
    one_line_error(cli(*d, "users", "create", "carol", "--role", "admin", "--password-stdin", stdin="short\n"),
                   "at least 8 characters")
    one_line_error(cli(*d, "users", "token", "nobody"), "no user named 'nobody'")
    assert cli(*d, "users", "list").stdout == before[1]
    one_line_error(cli("--data-dir", str(tmp_path / "missing"), "users", "list"), "does not exist")
    assert not (tmp_path / "missing").exists()
    one_line_error(cli("users", "list"), "no data dir")
    (ws / "illusion-studio.toml").write_text("port = 'eighty'\n")
    one_line_error(cli(*d, "users", "list"), "illusion-studio.toml: port")


def test_uninitialised_workspace_is_explained(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    one_line_error(cli("--data-dir", str(tmp_path / "empty"), "users", "list"), "not initialised")


def test_synth_writes_videos(tmp_path: Path) -> None:
    result = cli("synth", str(tmp_path / "out"), "--videos", "2", "--seed", "7", "--frames", "2", "--size", "96x64")
    assert result.returncode == 0, result.stderr
    paths = [Path(p) for p in result.stdout.split()]
    assert len(paths) == 2 and all((p / "scene.json").is_file() for p in paths)
    one_line_error(cli("synth", str(tmp_path / "o2"), "--size", "big"), "is not WIDTHxHEIGHT")


def test_data_dir_option_beats_the_environment(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    assert cli("--data-dir", str(b), "init", env={"ILLUSION_STUDIO_HOME": str(a)}).returncode == 0
    assert (b / "illusion-studio.db").is_file() and not a.exists()


def test_help_loads_no_subcommand_and_no_torch() -> None:
    """`illusion-studio --help` and `runs --help` list commands from their summaries: no torch, no
    database layer, no benchmarks (they took 3–5 s to start before)."""
    probe = ("import sys\nfrom webapp.cli import main\nfor args in (['--help'], ['runs', '--help']):\n"
             "    try:\n        main(args)\n    except SystemExit:\n        pass\n"
             "print(sorted(m for m in ('torch', 'sqlalchemy', 'alembic', 'webapp.cli.bench', 'model') if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().splitlines()[-1] == "[]"
    assert "list     Every run" in result.stdout


def test_the_command_list_says_what_each_command_says_of_itself() -> None:
    from webapp.cli import COMMANDS, main

    context = click.Context(main)
    for name, (_, _, summary) in COMMANDS.items():
        command = main.get_command(context, name)
        assert command is not None and command.get_short_help_str(limit=1000) == summary, name
