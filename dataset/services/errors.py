"""Errors services raise; the web layer maps them to HTTP statuses, the CLI to one-line messages."""


class ServiceError(Exception):
    """Base class; ``status`` is the HTTP status that fits."""

    status = 400


class InvalidInput(ServiceError):
    status = 400


class FieldError(InvalidInput):
    """Bad input in one named field of a request (a launch form's): answers carry the field, so a
    form can show the reason next to it."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}" if field else reason)
        self.field, self.reason = field, reason


class NotFound(ServiceError):
    status = 404


class Conflict(ServiceError):
    status = 409


class Unavailable(ServiceError):
    """A service the request needs (the job queue) is down; try again later."""

    status = 503
