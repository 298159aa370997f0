"""Who a request acts for, and what they may see: shared by every shell (API, dashboard)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, TypeVar

from backend.db.models import User
from backend.services.errors import NotFound


@dataclass(frozen=True)
class Principal:
    """Who a request acts for: a user's id, name and admin flag, detached from any session (so
    it can be cached between requests)."""

    id: int
    name: str
    is_admin: bool

    @classmethod
    def of(cls, user: User) -> Principal:
        return cls(id=user.id, name=user.name, is_admin=bool(user.is_admin))


class Owned(Protocol):
    """A row with an owner (an ORM object or a selected row)."""

    @property
    def owner_id(self) -> int: ...


O = TypeVar("O", bound=Owned)


def owned(user: Principal, obj: O | None, what: str, obj_id: int) -> O:
    """`obj` if the user may see it; otherwise NotFound, so other owners' ids reveal nothing."""
    if obj is None or (not user.is_admin and obj.owner_id != user.id):
        raise NotFound(f"no {what} with id {obj_id}")
    return obj
