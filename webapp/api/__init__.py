"""The JSON API, ``/api/v1``; described by ``/api/v1/openapi.json``. One module per topic."""

from webapp.api import annotate, core, evaluations, review, runs, samples, videos  # noqa: F401  (they attach their routes)
from webapp.api.blueprint import api

__all__ = ["api"]
