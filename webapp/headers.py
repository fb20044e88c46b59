"""Security headers on every response: CSP, framing, sniffing, referrer, HSTS under HTTPS.

The pages run only the app's own module scripts; inline ``style=""`` attributes carry computed
values (bar widths, colour ramps), so style attributes are allowed but not inline ``<style>``
or scripts. viser's prebuilt 3D client (``/viser/…``) injects its own ``<style>`` elements,
evaluates strings and starts workers from blobs: its routes get a policy of their own.
"""

from __future__ import annotations

from flask import Flask, Response, request

from dataset.settings import Settings

COMMON = ("default-src 'self'", "base-uri 'self'", "form-action 'self'", "frame-ancestors 'self'",
          "object-src 'none'", "img-src 'self' data: blob:", "font-src 'self' data:")
PAGES = "; ".join((*COMMON, "script-src 'self'", "style-src 'self'", "style-src-attr 'unsafe-inline'",
                   "connect-src 'self'"))
VISER_PREFIX = "/viser/"
# The client boots from an inline script, injects more at run time (their hashes change with
# each viser release) and evaluates strings: allowed on these static vendor routes alone.
VISER = "; ".join((*COMMON, "script-src 'self' 'unsafe-inline' 'unsafe-eval' blob:", "worker-src 'self' blob:",
                   "style-src 'self' 'unsafe-inline'", "connect-src 'self' blob: data:"))


def init_headers(app: Flask, settings: Settings) -> None:
    @app.after_request
    def _security_headers(response: Response) -> Response:
        h = response.headers
        h.setdefault("Content-Security-Policy", VISER if request.path.startswith(VISER_PREFIX) else PAGES)
        h.setdefault("X-Frame-Options", "SAMEORIGIN")  # for browsers without frame-ancestors
        h.setdefault("X-Content-Type-Options", "nosniff")
        h.setdefault("Referrer-Policy", "same-origin")
        if settings.https:
            h.setdefault("Strict-Transport-Security", "max-age=31536000")
        return response
