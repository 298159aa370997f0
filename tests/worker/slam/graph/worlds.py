"""Test worlds and logs for graph SLAM: a corridor ring, two identical rooms, and a driven log
with drifting (Stage) odometry recorded in memory."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tests.worker.slam.helpers import box_scan
from worker.sim.drivers import FollowParams, WaypointFollower
from worker.sim.laser import LaserSpec
from worker.sim.simulator import SimParams, Simulator
from worker.slam.graph.match_kernels import scan_points
from worker.world.world import World

RES = 0.05  # [m]


def _grid(width_m: float, height_m: float) -> np.ndarray:
    return np.ones((int(round(height_m / RES)), int(round(width_m / RES))), dtype=bool)


def _free(occ: np.ndarray, x0: float, y0: float, x1: float, y1: float) -> None:
    occ[
        int(round(y0 / RES)) : int(round(y1 / RES)), int(round(x0 / RES)) : int(round(x1 / RES))
    ] = False


def corridor_ring() -> World:
    """A 2 m wide corridor around a 19 x 11 m block (outer 23 x 15 m), with a 1 x 1 m niche in
    the left corridor near the start, so the place where the loop closes has some shape."""
    occ = _grid(24.0, 16.0)
    _free(occ, 0.5, 0.5, 23.5, 15.5)
    occ[int(2.5 / RES) : int(13.5 / RES), int(2.5 / RES) : int(21.5 / RES)] = True
    _free(occ, 2.5, 4.0, 3.5, 5.0)  # niche
    return World.from_array(occ, RES, start_pose=(1.5, 3.0, np.pi / 2), name="ring")


RING_PATH = np.array(
    [[1.5, 14.5], [22.5, 14.5], [22.5, 1.5], [1.5, 1.5], [1.5, 8.0]]
)  # once round, then up past the start and the niche


def twin_rooms() -> World:
    """Two identical 3 x 3 m rooms 3.3 m apart (a 0.3 m wall between them), each with the same
    pillar in its top-left corner and a 1 m door onto a corridor below: from inside, one room
    looks like the other shifted by 3.3 m."""
    occ = _grid(9.0, 8.0)
    for x0 in ROOMS_X:
        _free(occ, x0, 4.0, x0 + 3.0, 7.0)
        occ[int(6.1 / RES) : int(6.5 / RES), int((x0 + 0.5) / RES) : int((x0 + 0.9) / RES)] = True
        _free(occ, x0 + 1.0, 3.5, x0 + 2.0, 4.0)  # door
    _free(occ, 0.5, 1.5, 8.5, 3.5)  # corridor
    return World.from_array(occ, RES, start_pose=(2.5, 4.7, 0.0), name="twins")


ROOMS_X = (1.0, 4.3)  # [m] left edges of the two rooms


def _room_loop(x0: float) -> list[list[float]]:
    return [[x0 + 2.4, 4.7], [x0 + 2.4, 6.3], [x0 + 1.4, 6.3], [x0 + 1.4, 4.7], [x0 + 2.4, 4.7],
            [x0 + 2.4, 6.3], [x0 + 1.4, 6.3], [x0 + 1.4, 4.7]]  # fmt: skip


TWIN_PATH = np.array(
    _room_loop(ROOMS_X[0])
    + [[2.5, 4.3], [2.5, 2.5], [5.8, 2.5], [5.8, 4.3]]
    + _room_loop(ROOMS_X[1])
)  # twice round the first room, through the corridor, twice round the second


@dataclass(frozen=True, eq=False)
class Log:
    """A recorded drive: t (N,), pose_gt (N, 3), pose_odom (N, 3), ranges (N, B)."""

    t: np.ndarray
    pose_gt: np.ndarray
    pose_odom: np.ndarray
    ranges: np.ndarray
    laser: object
    odom_factors: np.ndarray | None = None  # (3,) the simulator's per-run error factors


def drive(
    world: World,
    waypoints: np.ndarray,
    seed: int,
    odom_error: float,
    laser: LaserSpec | None = None,
    odom_factors: tuple[float, float, float] | None = None,
) -> Log:
    """Follow the waypoints on the true pose with Stage odometry whose per-run error factors
    are uniform in +-odom_error / 2 (or exactly odom_factors: x, y, theta), logging every
    0.1 s scan."""
    params = SimParams(odom_error=(odom_error, odom_error, odom_error), laser=laser or LaserSpec())
    sim = Simulator(world, params, np.random.default_rng(seed))
    if odom_factors is not None:
        sim.odom_error_factors = np.asarray(odom_factors, dtype=float)
    follower = WaypointFollower(waypoints, FollowParams(v_max=0.8, tolerance=0.3))
    t, gt, odom, ranges = [], [], [], []
    for _ in range(20000):
        ranges.append(sim.scan())
        t.append(sim.t)
        gt.append(sim.pose_gt)
        odom.append(sim.pose_odom)
        if follower.finished:
            break
        sim.step(*follower.command(sim.pose_gt))
    return Log(
        np.array(t), np.array(gt), np.array(odom), np.array(ranges), params.laser,
        sim.odom_error_factors.copy(),
    )  # fmt: skip


BOX_ROOM = (0.0, 0.0, 8.0, 5.0)  # [m] an 8 x 5 m room (x0, y0, x1, y1)


def box_points(pose, laser, box=BOX_ROOM) -> np.ndarray:
    """(M, 2) [m, robot frame] the graph matcher's scan points of a closed-form scan of the
    axis-aligned `box` from `pose` (a point every 5 cm, beams to 29 m)."""
    a = laser.angles
    return scan_points(box_scan(pose, a, box), np.cos(a), np.sin(a), 29.0, 0.05)


def to_map(pose, pts) -> np.ndarray:
    """(M, 2) robot-frame points `pts` placed at `pose` (3,)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.column_stack([pose[0] + c * pts[:, 0] - s * pts[:, 1],
                            pose[1] + s * pts[:, 0] + c * pts[:, 1]])  # fmt: skip
