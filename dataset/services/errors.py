"""Errors services raise; the web layer maps them to HTTP statuses, the CLI to one-line messages."""


class ServiceError(Exception):
    """Base class; ``status`` is the HTTP status that fits."""

    status = 400


class InvalidInput(ServiceError):
    status = 400


class NotFound(ServiceError):
    status = 404


class Conflict(ServiceError):
    status = 409


class Unavailable(ServiceError):
    """A service the request needs (the job queue) is down; try again later."""

    status = 503
