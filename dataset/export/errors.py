"""The one exception of export and import: a dataset folder or request that cannot be used as it is."""

from __future__ import annotations

from dataset.services.errors import InvalidInput


class LayoutError(InvalidInput):
    """A dataset folder that is not what its format says, or an output that cannot be written.

    The message names the file and what is wrong with it, so a user can fix it.
    """
