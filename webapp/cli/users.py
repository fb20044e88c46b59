"""`illusion-studio users …`: create users, issue API tokens, list them."""

from __future__ import annotations

import sys

import click
from sqlalchemy import select

from dataset.db import transaction
from dataset.models import Role, User
from dataset.services import users as user_service
from webapp.cli.errors import service_errors
from webapp.cli.state import CliState, pass_state


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
    if password_stdin:
        password = sys.stdin.readline().rstrip("\r\n")
    else:
        password = click.prompt("Password", hide_input=True, confirmation_prompt=True)
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


@users.command("list")
@pass_state
def list_users(state: CliState) -> None:
    """List users and their roles."""
    with state.runtime.sessions() as s:
        for user in s.scalars(select(User).order_by(User.name)):
            click.echo(f"{user.name:<24} {user.role.value:<10} {'active' if user.active else 'disabled'}")
