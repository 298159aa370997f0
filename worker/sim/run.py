"""One standalone simulation: drive a robot through a World and write its CARMEN log and TUM
trajectories (`mapqual simulate`)."""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from worker.errors import InputError
from worker.evaluate.trajectory import Trajectory
from worker.evaluate.trajio import write_tum
from worker.sim.carmen import CarmenWriter
from worker.sim.drivers import FollowParams, Wanderer, WanderParams, WaypointFollower
from worker.sim.simulator import Collision, SimParams, Simulator
from worker.world.world import World

DriveMode = Literal["wander", "path"]


@dataclass(frozen=True)
class SimRunResult:
    """What one standalone simulation did."""

    world: str
    seed: int
    n_ticks: int  # logged time steps (scans)
    sim_time_s: float  # [s] simulated time covered by the log
    distance_m: float  # [m] true path length
    collisions: tuple[Collision, ...]
    path_completed: bool | None  # waypoints all reached (None when wandering)
    wall_time_s: float  # [s] CPU wall time of the run including writing the files
    files: tuple[str, ...]

    def to_json(self) -> dict:
        """A JSON-ready dict."""
        d = dataclasses.asdict(self)
        d["collisions"] = [dataclasses.asdict(c) for c in self.collisions]
        return d


def check_waypoints(world: World, waypoints: np.ndarray) -> None:
    """Every waypoint must lie on a free cell of the map."""
    for k, (x, y) in enumerate(waypoints, start=1):
        if not world.is_free(x, y):
            raise InputError(f"waypoint {k} ({x:g}, {y:g}) is not on a free cell of {world.name}")


def run_simulation(
    world: World,
    out_dir: str | Path,
    *,
    seed: int = 0,
    duration_s: float = 600.0,
    drive: DriveMode = "wander",
    waypoints: np.ndarray | None = None,
    params: SimParams | None = None,
    wander: WanderParams | None = None,
    follow: FollowParams | None = None,
) -> SimRunResult:
    """Simulate for `duration_s` [s] (a path run ends early when its last waypoint is reached)
    and write `out_dir/sim.log` (CARMEN), `gt.tum`, `odom.tum` and `sim.json`.

    One Generator from `seed` drives everything, so the same arguments give the same bytes.
    """
    wall0 = time.perf_counter()
    params = params or SimParams()
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise InputError(f"duration must be > 0 s, got {duration_s:g}")
    if drive == "path":
        if waypoints is None or len(waypoints) == 0:
            raise InputError("--drive path needs waypoints (--path FILE)")
        check_waypoints(world, waypoints)
    elif drive != "wander":
        raise InputError(f"unknown drive mode {drive!r} (wander or path)")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    sim = Simulator(world, params, rng)
    wanderer = Wanderer(params.laser, rng, wander) if drive == "wander" else None
    follower = WaypointFollower(waypoints, follow) if drive == "path" else None
    n_steps = int(math.floor(duration_s / params.dt + 1e-9))
    poses_gt = np.empty((n_steps + 1, 3))
    poses_odom = np.empty((n_steps + 1, 3))
    comment = f"mapqual simulate: world {world.name}, seed {seed}, drive {drive}, " + json.dumps(
        dataclasses.asdict(params), sort_keys=True
    )
    n_ticks = 0
    with open(out / "sim.log", "w", encoding="utf-8", newline="\n") as fh:
        writer = CarmenWriter(fh, params.laser, comment=comment)
        for k in range(n_steps + 1):
            ranges = sim.scan()
            pose_gt, pose_odom = sim.pose_gt, sim.pose_odom
            v, w = sim.velocity
            writer.write_tick(sim.t, pose_gt, pose_odom, v, w, ranges)
            poses_gt[k] = pose_gt
            poses_odom[k] = pose_odom
            n_ticks = k + 1
            if k == n_steps or (follower is not None and follower.finished):
                break
            if wanderer is not None:
                v_cmd, w_cmd = wanderer.command(ranges, params.dt)
                if sim.in_contact:
                    v_cmd = -0.2  # back off a wall the wanderer touched
            else:
                v_cmd, w_cmd = follower.command(pose_gt)
            sim.step(v_cmd, w_cmd)
    t = params.dt * np.arange(n_ticks)
    write_tum(out / "gt.tum", Trajectory(t, poses_gt[:n_ticks]))
    write_tum(out / "odom.tum", Trajectory(t, poses_odom[:n_ticks]))
    steps = np.diff(poses_gt[:n_ticks, :2], axis=0)
    result = SimRunResult(
        world=world.name,
        seed=seed,
        n_ticks=n_ticks,
        sim_time_s=float(t[-1]),
        distance_m=float(np.hypot(steps[:, 0], steps[:, 1]).sum()),
        collisions=tuple(sim.collisions),
        path_completed=None if follower is None else follower.finished,
        wall_time_s=0.0,
        files=tuple(str(out / f) for f in ("sim.log", "gt.tum", "odom.tum", "sim.json")),
    )
    result = dataclasses.replace(result, wall_time_s=time.perf_counter() - wall0)
    summary = result.to_json() | {"params": dataclasses.asdict(params)}
    # Keep sim.json identical across runs with the same seed, wherever they are written.
    summary.pop("wall_time_s")
    summary["files"] = [Path(f).name for f in result.files]
    (out / "sim.json").write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")
    return result
