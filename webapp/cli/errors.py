"""Turn service errors into one-line CLI errors (exit status 1)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import click

from dataset.services.errors import ServiceError


@contextmanager
def service_errors() -> Iterator[None]:
    try:
        yield
    except ServiceError as exc:
        raise click.ClickException(str(exc)) from None
