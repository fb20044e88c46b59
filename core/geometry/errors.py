"""Exception types of the geometry core: every bad input ends in one of these, never in garbage."""

from __future__ import annotations


class GeometryError(ValueError):
    """Base class: the message names the offending input and what was expected."""


class InputError(GeometryError):
    """An array of the wrong shape, dtype or content (e.g. all-NaN disparity, empty mask)."""


class DegenerateSupportError(GeometryError):
    """The support points do not define a plane (too few, collinear or coincident)."""


class ScaleSearchError(GeometryError):
    """No disparity scale reaches the requested fraction τ of in-image pixels."""


class CalibrationError(GeometryError):
    """A calibration file is missing, malformed or physically implausible."""


class InpaintError(GeometryError):
    """An inpainting backend is unknown, unconfigured or returned an unusable result."""
