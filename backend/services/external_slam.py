"""External SLAM programs over the API: users pick one of the administrator's programs by name
(MAPQUAL_EXTERNAL_SLAM); a command in a request is refused, never run; the time-outs a run
asks for are capped by the server's settings, and the program's memory and CPU limits are the
server's."""

from __future__ import annotations

import copy
from typing import Any

from backend.core.config import Settings
from worker.errors import InputError
from worker.slam.external.params import ExternalSlamParams

# The time-outs a run may ask for, and the settings that cap them.
TIMEOUT_CAPS = {
    "start_timeout_s": "external_start_timeout_max_s",
    "step_timeout_s": "external_step_timeout_max_s",
    "close_timeout_s": "external_close_timeout_max_s",
}
LIMITS = ("memory_mb", "cpu_s")  # the server's, never a request's


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
    for key in ("command", *LIMITS):
        if key in external:
            raise InputError(
                f"slam.external.{key} cannot be given over the API: the server runs only the "
                "programs its administrator registered; give "
                f"slam.external.name, one of: {choices}"
            )
    check_timeouts(external, settings)
    name = external.get("name")
    if not isinstance(name, str) or name not in registered:
        raise InputError(f"slam.external.name {name!r} is not a registered program: {choices}")
    out = copy.deepcopy(overrides)
    out["slam"]["external"] = {
        **external,
        "command": list(registered[name]),
        "memory_mb": settings.external_memory_mb,
        "cpu_s": settings.external_cpu_s,
    }
    for key, setting in TIMEOUT_CAPS.items():  # a default over a lower cap: the cap
        default = ExternalSlamParams.__dataclass_fields__[key].default
        if key not in external and default > getattr(settings, setting):
            out["slam"]["external"][key] = getattr(settings, setting)
    return out


def check_timeouts(external: dict[str, Any], settings: Settings) -> None:
    """400 for a time-out over the administrator's cap (or not a number), naming the cap."""
    for key, setting in TIMEOUT_CAPS.items():
        if key not in external:
            continue
        value = external[key]
        cap = getattr(settings, setting)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(f"slam.external.{key} must be a number [s], got {value!r}")
        if not value <= cap:  # NaN is refused too
            env = Settings.model_fields[setting].alias
            raise InputError(
                f"slam.external.{key} = {value:g} s is over this server's cap of {cap:g} s "
                f"(setting {setting}, environment {env})"
            )
