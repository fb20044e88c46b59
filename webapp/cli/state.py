"""What every subcommand shares: the data dir given to the group, settings and runtime built lazily."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import click

if TYPE_CHECKING:  # the database layer loads when a command first needs it, not for `--help`
    from dataset.settings import Settings
    from webapp.runtime import Runtime


@dataclass
class CliState:
    data_dir: Path | None
    _settings: Settings | None = field(default=None, repr=False)
    _runtime: Runtime | None = field(default=None, repr=False)

    @property
    def settings(self) -> Settings:
        """The workspace's settings; a missing data dir or bad settings file is a one-line error."""
        from dataset.settings import SettingsError, load_settings

        if self._settings is None:
            try:
                self._settings = load_settings(self.data_dir)
            except SettingsError as exc:
                raise click.ClickException(str(exc)) from None
        return self._settings

    @property
    def runtime(self) -> Runtime:
        """DB, media and queue of an initialised workspace."""
        from dataset.db import schema_is_current
        from webapp.runtime import Runtime

        if self._runtime is None:
            rt = Runtime(self.settings)
            if not schema_is_current(rt.engine):
                raise click.ClickException(
                    f"the database of {self.settings.home} is not initialised or not up to date; "
                    f"run `illusion-studio --data-dir {self.settings.home} init`")
            self._runtime = rt
        return self._runtime


pass_state = click.make_pass_decorator(CliState)
