"""Server-rendered pages: one blueprint per audience (each module's ``bp``), plus media files."""

from webapp.views import admin, annotate, auth, dashboard, evaluations, exports, ingest, jobs, models, review
from webapp.views.media import media
from webapp.views.samples import samples

BLUEPRINTS = (auth.bp, dashboard.bp, jobs.bp, annotate.bp, review.bp, ingest.bp, admin.bp, media, samples, models.bp,
              evaluations.bp, exports.bp)
