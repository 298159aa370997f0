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
from worker.sim.params import SimParams
from worker.sim.simulator import Collision, Simulator
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
    _check_inputs(world, duration_s, drive, waypoints)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    sim = Simulator(world, params, rng)
    follower = WaypointFollower(waypoints, follow) if drive == "path" else None
    driver = follower or Wanderer(params.laser, rng, wander)
    n_steps = int(math.floor(duration_s / params.dt + 1e-9))
    comment = f"mapqual simulate: world {world.name}, seed {seed}, drive {drive}, " + json.dumps(
        dataclasses.asdict(params), sort_keys=True
    )
    with open(out / "sim.log", "w", encoding="utf-8", newline="\n") as fh:
        writer = CarmenWriter(fh, params.laser, comment=comment)
        poses_gt, poses_odom = _drive_and_log(sim, writer, driver, n_steps)
    t = params.dt * np.arange(len(poses_gt))
    write_tum(out / "gt.tum", Trajectory(t, poses_gt))
    write_tum(out / "odom.tum", Trajectory(t, poses_odom))
    steps = np.diff(poses_gt[:, :2], axis=0)
    result = SimRunResult(
        world=world.name,
        seed=seed,
        n_ticks=len(t),
        sim_time_s=float(t[-1]),
        distance_m=float(np.hypot(steps[:, 0], steps[:, 1]).sum()),
        collisions=tuple(sim.collisions),
        path_completed=None if follower is None else follower.finished,
        wall_time_s=time.perf_counter() - wall0,
        files=tuple(str(out / f) for f in ("sim.log", "gt.tum", "odom.tum", "sim.json")),
    )
    summary = result.to_json() | {"params": dataclasses.asdict(params)}
    # Keep sim.json identical across runs with the same seed, wherever they are written.
    summary.pop("wall_time_s")
    summary["files"] = [Path(f).name for f in result.files]
    (out / "sim.json").write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")
    return result


def _check_inputs(world: World, duration_s: float, drive: str, waypoints) -> None:
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise InputError(f"duration must be > 0 s, got {duration_s:g}")
    if drive == "path":
        if waypoints is None or len(waypoints) == 0:
            raise InputError("--drive path needs waypoints (--path FILE)")
        check_waypoints(world, waypoints)
    elif drive != "wander":
        raise InputError(f"unknown drive mode {drive!r} (wander or path)")


def _drive_and_log(
    sim: Simulator,
    writer: CarmenWriter,
    driver: Wanderer | WaypointFollower,
    n_steps: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Log a tick (scan, poses) at t = 0, dt, ..., n_steps * dt, stepping the robot between
    ticks; a path run stops after the tick at which its last waypoint is reached.

    Returns the logged `pose_gt`, `pose_odom`, each `(N, 3)` [x, y, theta].
    """
    dt = sim.params.dt
    poses_gt = np.empty((n_steps + 1, 3))
    poses_odom = np.empty((n_steps + 1, 3))
    for k in range(n_steps + 1):
        ranges = sim.scan()
        pose_gt, pose_odom = sim.pose_gt, sim.pose_odom
        v, w = sim.velocity
        writer.write_tick(sim.t, pose_gt, pose_odom, v, w, ranges)
        poses_gt[k] = pose_gt
        poses_odom[k] = pose_odom
        if k == n_steps:
            break
        if isinstance(driver, WaypointFollower):
            if driver.finished:
                break
            v_cmd, w_cmd = driver.command(pose_gt)
        else:
            v_cmd, w_cmd = driver.command(ranges, dt)
            if sim.in_contact:
                v_cmd = -0.2  # [m/s] back off a wall the wanderer touched
        sim.step(v_cmd, w_cmd)
    return poses_gt[: k + 1], poses_odom[: k + 1]
