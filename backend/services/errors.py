"""The service layer's typed errors. Services never speak HTTP: the API maps each error to its
status in one place (`backend.api.errors`), and other shells (the CLI, batch) print it."""

from __future__ import annotations


class ServiceError(Exception):
    """A request the service refuses; `detail` is what the client is told."""

    def __init__(self, detail: str, headers: dict[str, str] | None = None):
        super().__init__(detail)
        self.detail = detail
        self.headers = headers


class Invalid(ServiceError):
    """The request itself is wrong (an unsafe or repeated file name, files that make no
    floorplan)."""


class TooLarge(ServiceError):
    """What was sent is over a size limit of the settings (an image's pixels)."""


class NotFound(ServiceError):
    """No such object, or one the caller may not see (other owners' ids reveal nothing)."""


class Conflict(ServiceError):
    """The object is not in a state that allows the request (a world not ready, a job done)."""


class QuotaExceeded(ServiceError):
    """The request would take the owner past a quota of the settings."""


class Unavailable(ServiceError):
    """A part the request needs (the job queue) cannot be reached; trying later may work."""
