"""`illusion-studio users …`: create users, issue API tokens, list them."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TypeVar

import click
from sqlalchemy import select
from sqlalchemy.orm import Session

from dataset.db import transaction
from dataset.services import users as user_service
from dataset.tables import Role, User
from webapp.cli.errors import service_errors
from webapp.cli.state import CliState, pass_state

T = TypeVar("T")


@click.group()
def users() -> None:
    """Manage users and API tokens."""


@users.command("create")
@click.argument("name")
@click.option("--role", required=True, help=f"One of: {', '.join(Role)}.")
@click.option("--password-stdin", is_flag=True, help="Read the password from the first line of stdin.")
@pass_state
def create(state: CliState, name: str, role: str, password_stdin: bool) -> None:
    """Create user NAME with ROLE (asks for the password unless --password-stdin)."""
    with service_errors():
        parsed = user_service.parse_role(role)  # before prompting: a typo should not cost a password
    password = _read_password(password_stdin)
    with service_errors(), transaction(state.runtime.sessions) as s:
        user_service.create_user(s, name, parsed, password)
    click.echo(f"created {parsed.value} {name}")


@users.command("token")
@click.argument("name")
@click.option("--label", default="", help="A note to recognise the token by.")
@pass_state
def token(state: CliState, name: str, label: str) -> None:
    """Issue an API token for NAME and print it (last line) — it is shown only once."""
    with service_errors(), transaction(state.runtime.sessions) as s:
        value = user_service.issue_token(s, user_service.get_user(s, name), label)
    click.echo(f"Token for {name} (send as 'Authorization: Bearer <token>'):", err=True)
    click.echo(value)


def _read_password(password_stdin: bool) -> str:
    if password_stdin:
        return sys.stdin.readline().rstrip("\r\n")
    return click.prompt("Password", hide_input=True, confirmation_prompt=True)


def _manage(state: CliState, name: str, change: Callable[[Session, User], T]) -> T:
    """Apply one audited change to user NAME (the actor is the CLI: no user); returns its result."""
    with service_errors(), transaction(state.runtime.sessions) as s:
        return change(s, user_service.get_user(s, name))


@users.command("deactivate")
@click.argument("name")
@pass_state
def deactivate(state: CliState, name: str) -> None:
    """Deactivate NAME: their sessions end and their API tokens are revoked for good."""
    count = _manage(state, name, lambda s, u: user_service.set_active(s, None, u, False))
    click.echo(f"deactivated {name}: sessions ended, {user_service.revoked_words(count)} (reactivating does not bring them back)")


@users.command("reactivate")
@click.argument("name")
@pass_state
def reactivate(state: CliState, name: str) -> None:
    """Let NAME log in again; API tokens revoked at deactivation stay revoked."""
    _manage(state, name, lambda s, u: user_service.set_active(s, None, u, True))
    click.echo(f"reactivated {name}: they can log in again; no API token came back "
               f"(issue one with 'illusion-studio users token {name}')")


@users.command("role")
@click.argument("name")
@click.argument("role")
@pass_state
def set_role(state: CliState, name: str, role: str) -> None:
    """Give NAME the role ROLE (their sessions end)."""
    _manage(state, name, lambda s, u: user_service.set_role(s, None, u, role))
    click.echo(f"{name} is now {role}")


@users.command("password")
@click.argument("name")
@click.option("--password-stdin", is_flag=True, help="Read the password from the first line of stdin.")
@pass_state
def reset_password(state: CliState, name: str, password_stdin: bool) -> None:
    """Set a new password for NAME (their sessions end, their API tokens are revoked for good)."""
    password = _read_password(password_stdin)
    count = _manage(state, name, lambda s, u: user_service.reset_password(s, None, u, password))
    click.echo(f"new password set for {name}: sessions ended, {user_service.revoked_words(count)}")


@users.command("revoke-tokens")
@click.argument("name")
@pass_state
def revoke_tokens(state: CliState, name: str) -> None:
    """Delete every API token of NAME."""
    count = _manage(state, name, lambda s, u: user_service.revoke_tokens(s, None, u))
    click.echo(f"revoked {count} token(s) of {name}")


@users.command("list")
@pass_state
def list_users(state: CliState) -> None:
    """List users and their roles."""
    with state.runtime.sessions() as s:
        for user in s.scalars(select(User).order_by(User.name)):
            click.echo(f"{user.name:<24} {user.role.value:<10} {'active' if user.active else 'disabled'}")
