"""External SLAM programs over the API: users pick one of the administrator's programs by name
(MAPQUAL_EXTERNAL_SLAM); a command in a request is refused, never run."""

from __future__ import annotations

import copy
from typing import Any

from backend.core.config import Settings
from worker.errors import InputError


def resolve_external(
    overrides: dict[str, Any], settings: Settings, algorithm: str | None = None
) -> dict[str, Any]:
    """`overrides` with slam.external.command filled in from the registered program named by
    slam.external.name (InputError, a 400, for a command given or a name not registered).
    `algorithm`: the job's, when it is given apart from the overrides."""
    slam = overrides.get("slam")
    external = slam.get("external") if isinstance(slam, dict) else None
    registered = settings.external_slam
    choices = ", ".join(map(repr, sorted(registered))) or "none are registered on this server"
    if external is None:
        if (algorithm or overrides.get("algorithm")) == "external":
            raise InputError(
                "the external algorithm runs a program the administrator registered: give "
                f"params.slam.external.name, one of: {choices}"
            )
        return overrides
    if not isinstance(external, dict):
        raise InputError("slam.external must be a mapping: {name: <a registered program>}")
    if "command" in external:
        raise InputError(
            "slam.external.command cannot be given over the API: the server runs only the "
            f"programs its administrator registered; give slam.external.name, one of: {choices}"
        )
    name = external.get("name")
    if not isinstance(name, str) or name not in registered:
        raise InputError(f"slam.external.name {name!r} is not a registered program: {choices}")
    out = copy.deepcopy(overrides)
    out["slam"]["external"] = {**external, "command": list(registered[name])}
    return out
