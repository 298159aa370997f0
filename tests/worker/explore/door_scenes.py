"""Door scenes for the door passage's tests: maps with a wall and a door, the settings, and a
unicycle driven by the passage."""

from __future__ import annotations

import math

import numpy as np

from worker.explore.costmap import GlobalCostmap
from worker.explore.door import DoorPass
from worker.explore.door_geometry import find_door, path_ahead
from worker.explore.flat_params import explore_params
from worker.explore.params import ExploreParams

RES = 0.05
WALL_X = 60  # the wall's cells: x in [3.0, 3.1) m (two cells thick)


def door_map(door_cells: int) -> np.ndarray:
    """(80, 120) SLAM probabilities: free, a wall two cells thick at x = 3.0 m with a door
    of `door_cells` free cells centred on y = 2.0 m."""
    prob = np.full((80, 120), 0.02, dtype=np.float32)
    prob[:, WALL_X : WALL_X + 2] = 0.9
    prob[40 - door_cells // 2 : 40 - door_cells // 2 + door_cells, WALL_X : WALL_X + 2] = 0.02
    return prob


def door_params(**kw) -> ExploreParams:
    return explore_params(door_align=True, **kw)


def door_pass(p: ExploreParams, range_noise: float = 0.0) -> DoorPass:
    """The door passage with the settings `p`, as the navigator makes it."""
    back_out_speed = p.recovery.back_out_speed_ratio * p.dwa.escape_vel
    return DoorPass(
        p.doors, p.costmap, p.dwa, back_out_speed, p.safety.safety_distance, range_noise
    )


def find_on_path(path, x, y, local, p):
    """find_door on the path ahead of (x, y)."""
    return find_door(*path_ahead(path, x, y, p.doors), local, p.doors)


def drive_through(
    p: ExploreParams,
    cm: GlobalCostmap,
    pose,
    path,
    steps: int = 300,
    replan=None,
    *,
    range_noise: float = 0.0,
    phases: list[str] | None = None,
):
    """Unicycle integration of DoorPass's commands at 10 Hz; the poses and the kinds.
    replan(x, y, door): a new path for a new goal (the passage told so), or None.
    range_noise: the passage's (default 0); phases: a list that gets the passage's phase
    after each command."""
    door = door_pass(
        p,
        range_noise,
    )
    poses, kinds = [np.array(pose, dtype=float)], []
    x, y, th = pose
    for _ in range(steps):
        new = None if replan is None else replan(x, y, door)
        if new is not None:
            path = new
            door.new_goal()  # as Navigator._choose does
        cmd = door.command(np.array([x, y, th]), path, cm)
        if cmd is None:
            break
        v, w, kind = cmd
        kinds.append(kind)
        if phases is not None:
            phases.append(door.phase)
        for _ in range(10):  # 0.1 s in ten sub-steps
            x += v * math.cos(th) * 0.01
            y += v * math.sin(th) * 0.01
            th += w * 0.01
        poses.append(np.array([x, y, th]))
    return np.array(poses), kinds, door


def footprint_hits_wall(cm: GlobalCostmap, x: float, y: float, th: float, half: float) -> bool:
    """Whether the exact square footprint covers a map obstacle cell (sampled densely)."""
    c, s = math.cos(th), math.sin(th)
    for u in np.linspace(-half, half, 17):
        for v in np.linspace(-half, half, 17):
            px, py = x + u * c - v * s, y + u * s + v * c
            ix, iy = int(math.floor(px / RES)), int(math.floor(py / RES))
            if cm.map_lethal[iy, ix]:
                return True
    return False


def thick_wall_map(door_cells: int, thickness_cells: int = 8) -> np.ndarray:
    """(80, 120) SLAM probabilities: a wall `thickness_cells` thick from x = 3.0 m with a
    door of `door_cells` free cells centred on y = 2.0 m."""
    prob = np.full((80, 120), 0.02, dtype=np.float32)
    prob[:, WALL_X : WALL_X + thickness_cells] = 0.9
    lo = 40 - door_cells // 2
    prob[lo : lo + door_cells, WALL_X : WALL_X + thickness_cells] = 0.02
    return prob


def in_wall_poses(poses: np.ndarray, half: float, x0: float, x1: float) -> np.ndarray:
    """The poses whose footprint reaches into the wall's x range [x0, x1)."""
    reach = half * (np.abs(np.cos(poses[:, 2])) + np.abs(np.sin(poses[:, 2])))
    return poses[(poses[:, 0] + reach > x0) & (poses[:, 0] - reach < x1)]
