"""The one list of SLAM algorithms a run may use: name -> factory, description and kind.

`make_slam(name, laser, params, rng)` makes one. Light on purpose (no kernels are imported until
a factory is called): the CLI's choices, the API's enum, the dashboard's form and the batch's
validation are all read from here. Adding an
algorithm is one `register(...)` call; the factory imports its own module when it is called.
Installed packages add in-process algorithms through the `mapqual.slam` entry points group
(`load_plugins`); programs in other languages run as "external" (worker.slam.external).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import TYPE_CHECKING, Literal

import numpy as np

from worker.errors import InputError
from worker.slam.params import SlamParams

if TYPE_CHECKING:
    from worker.slam.base import LaserGeometry, SlamAlgorithm

log = logging.getLogger("mapqual.slam")
ENTRY_POINTS_GROUP = "mapqual.slam"

SlamName = str  # a registered name ("rbpf", "odometry", ...)
SlamKind = Literal["slam", "baseline", "oracle"]
SlamFactory = Callable[["LaserGeometry", SlamParams, "np.random.Generator"], "SlamAlgorithm"]


@dataclass(frozen=True)
class SlamEntry:
    """One algorithm: how to make it and what it is."""

    name: str
    factory: SlamFactory  # (laser, params, rng) -> a fresh SlamAlgorithm
    description: str  # one line, shown in the dashboard's form and the CLI's help
    kind: SlamKind  # slam: a real SLAM; baseline: a reference to beat; oracle: ground truth
    # whether the run maps and localises with the ground-truth pose (the exploration then
    # ignores the estimate); an oracle has no log to replay, so `mapqual slam` leaves it out
    ground_truth: bool = False
    # an offline algorithm (a third-party program run once over the whole log): `mapqual
    # slam` replays a log with it, a run (closed loop) cannot drive on it
    replay_only: bool = False


_REGISTRY: dict[str, SlamEntry] = {}


def register(
    name: str,
    factory: SlamFactory,
    description: str,
    kind: SlamKind = "slam",
    *,
    ground_truth: bool = False,
    replay_only: bool = False,
) -> SlamEntry:
    """Add an algorithm under `name` (unique); returns its entry."""
    if not name or not name.isidentifier():
        raise ValueError(f"SLAM algorithm name {name!r} must be a Python identifier")
    if name in _REGISTRY:
        raise ValueError(f"SLAM algorithm {name!r} is already registered")
    entry = SlamEntry(name, factory, description, kind, ground_truth, replay_only)
    _REGISTRY[name] = entry
    return entry


def entries() -> tuple[SlamEntry, ...]:
    """Every registered algorithm, in registration order."""
    return tuple(_REGISTRY.values())


def names(*, offline: bool = False) -> tuple[str, ...]:
    """Registered names a run can use; `offline`: those that can replay a recorded log
    instead (no oracle; the replay-only third-party programs included)."""
    if offline:
        return tuple(e.name for e in _REGISTRY.values() if not e.ground_truth)
    return tuple(e.name for e in _REGISTRY.values() if not e.replay_only)


def get(name: str) -> SlamEntry:
    """The entry of `name`, or InputError naming the choices."""
    entry = _REGISTRY.get(name)
    if entry is None:
        raise InputError(f"unknown SLAM algorithm {name!r}; choose one of: {', '.join(names())}")
    return entry


def make_slam(
    name: SlamName,
    laser: LaserGeometry,
    params: SlamParams | None = None,
    rng: np.random.Generator | None = None,
) -> SlamAlgorithm:
    """The SLAM algorithm `name` (one of `names()`) for this laser.

    params: None = the thesis defaults; rng: the run's generator (None = seed 0).
    """
    entry = get(name)  # InputError naming the choices
    params = SlamParams() if params is None else params
    rng = np.random.default_rng(0) if rng is None else rng
    return entry.factory(laser, params, rng)


def check_name(name: str) -> str:
    """`name` if it is registered (for validators: raises ValueError, one line, otherwise)."""
    entry = _REGISTRY.get(name)
    if entry is not None and entry.replay_only:
        raise ValueError(f"{name!r} replays recorded logs only (mapqual slam LOG), not a run")
    if entry is None:
        choices = ", ".join(map(repr, names()))
        raise ValueError(f"must be one of {choices}, not {name!r}")
    return name


def add_enum(schema: dict) -> None:
    """JSON Schema hook (pydantic's json_schema_extra): the names registered when the schema
    is made, as the string's `enum` (plugins registered after import included)."""
    schema["enum"] = list(names())


def _rbpf(laser: LaserGeometry, params: SlamParams, rng: np.random.Generator) -> SlamAlgorithm:
    from worker.slam.rbpf import RbpfSlam

    return RbpfSlam(laser, params, rng)


def _odometry(laser: LaserGeometry, params: SlamParams, rng: np.random.Generator) -> SlamAlgorithm:
    from worker.slam.odometry import OdometrySlam

    return OdometrySlam(laser, params)


register("rbpf", _rbpf, "rbpf (GMapping)", "slam")
register("odometry", _odometry, "odometry only", "baseline")
register("oracle", _odometry, "oracle (ground truth)", "oracle", ground_truth=True)


def _graph(laser: LaserGeometry, params: SlamParams, rng: np.random.Generator) -> SlamAlgorithm:
    from worker.slam.graph.slam import GraphSlam

    return GraphSlam(laser, params)


register("graph", _graph, "graph SLAM (pose graph, loop closure)", "slam")


def _external(laser: LaserGeometry, params: SlamParams, rng: np.random.Generator) -> SlamAlgorithm:
    from worker.slam.external.client import ExternalSlam

    return ExternalSlam(laser, params, rng)


register("external", _external, "an external SLAM program (slam.external)", "slam")


def _mrpt_rbpf(laser: LaserGeometry, params: SlamParams, rng: np.random.Generator) -> SlamAlgorithm:
    from worker.slam.mrpt.slam import rbpf_factory

    return rbpf_factory(laser, params, rng)


def _mrpt_icp(laser: LaserGeometry, params: SlamParams, rng: np.random.Generator) -> SlamAlgorithm:
    from worker.slam.mrpt.slam import icp_factory

    return icp_factory(laser, params, rng)


# third-party programs (Debian's mrpt-apps), offline: available when installed
register("mrpt_rbpf", _mrpt_rbpf, "MRPT rbpf-slam (third party, offline)", replay_only=True)
register("mrpt_icp", _mrpt_icp, "MRPT icp-slam (third party, offline)", replay_only=True)
EXTERNAL_PREFIX = "external:"  # an external program's label: external:NAME


def label(algorithm: str, slam: SlamParams | None = None) -> str:
    """What reports, tables, the database and the dashboard call a run's algorithm: its name,
    or `external:NAME` for an external program (two programs never share a row, and the
    label says at a glance that the program ran over the protocol)."""
    ext = slam.external if slam is not None else None
    if algorithm == "external" and ext is not None:
        return EXTERNAL_PREFIX + ext.name
    return algorithm


def parse_label(text: str) -> tuple[str, str | None]:
    """(algorithm, external program name or None) of a label: `external:mine` ->
    ("external", "mine"), `rbpf` -> ("rbpf", None)."""
    if text.startswith(EXTERNAL_PREFIX):
        return "external", text[len(EXTERNAL_PREFIX) :]
    return text, None


def _plugin_factory(ep: EntryPoint) -> SlamFactory:
    """A factory that imports the entry point's object when a run first needs it."""

    def factory(laser: LaserGeometry, params: SlamParams, rng: np.random.Generator):
        return ep.load()(laser, params, rng)

    return factory


def load_plugins(eps: tuple[EntryPoint, ...] | None = None) -> list[str]:
    """Register the `mapqual.slam` entry points (name = the algorithm, object = a factory
    `(laser, params, rng) -> SlamAlgorithm`), without importing them; the names added. A name
    that is taken or not an identifier is skipped with a warning."""
    found = tuple(entry_points(group=ENTRY_POINTS_GROUP)) if eps is None else eps
    added = []
    for ep in found:
        entry = _REGISTRY.get(ep.name)
        if entry is not None and getattr(entry.factory, "entry_point", None) == ep.value:
            continue  # already loaded
        try:
            factory = _plugin_factory(ep)
            factory.entry_point = ep.value  # type: ignore[attr-defined]
            register(ep.name, factory, f"{ep.name} (plugin {ep.value})", "slam")
        except ValueError as exc:
            log.warning("SLAM plugin %s = %s skipped: %s", ep.name, ep.value, exc)
            continue
        added.append(ep.name)
    return added


load_plugins()
