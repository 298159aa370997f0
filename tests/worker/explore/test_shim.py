"""Heading shim: turns on the spot to a path behind, backs out of a pocket it cannot turn in."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from worker.explore.costmap import GlobalCostmap, LocalCostmap
from worker.explore.params import ExploreParams
from worker.explore.shim import HeadingShim

RES = 0.05


def _local(points, pose, p):
    local = LocalCostmap(p.costmap, p.dwa, RES)
    if len(points):
        local.add_points(0.0, np.asarray(points, dtype=float))
    local.build(pose[0], pose[1], None, pose[2])
    return local


def _segment(x0, y0, x1, y1, step=0.01):
    n = int(math.hypot(x1 - x0, y1 - y0) / step) + 1
    return np.column_stack((np.linspace(x0, x1, n), np.linspace(y0, y1, n)))


def _until_rotate(shim, x, sense, obstacles, steps):
    """Drive pose `x` (in place) by the shim's commands at 10 Hz until it turns on the spot
    or `steps` run out; `sense()` gives (path, local costmap) at the current pose. The
    kinds of command, in order. Independent check each step: the robot's 0.4 m square
    never overlaps an obstacle point."""
    kinds = []
    for _ in range(steps):
        out = shim.command(x, 0.0, *sense())
        assert out is not None
        v, w, kind = out
        kinds.append(kind)
        if kind == "rotate":
            break
        x[0] += v * math.cos(x[2]) * 0.1
        x[1] += v * math.sin(x[2]) * 0.1
        x[2] += w * 0.1
        c, s = math.cos(x[2]), math.sin(x[2])
        u = (obstacles[:, 0] - x[0]) * c + (obstacles[:, 1] - x[1]) * s
        q = -(obstacles[:, 0] - x[0]) * s + (obstacles[:, 1] - x[1]) * c
        assert not np.any((np.abs(u) < 0.2) & (np.abs(q) < 0.2))
    return kinds


def _path_west(x0=3.0, y=3.0):
    return np.column_stack((np.linspace(x0, 0.5, 51), np.full(51, y)))


def test_path_ahead_is_left_to_the_dwa():
    p = ExploreParams()
    pose = np.array([3.0, 3.0, math.pi])
    assert (
        HeadingShim(p.dwa, p.costmap, p.recovery).command(
            pose, 0.0, _path_west(), _local([], pose, p)
        )
        is None
    )


def test_path_behind_in_the_open_turns_on_the_spot_until_released():
    p = ExploreParams()
    shim = HeadingShim(p.dwa, p.costmap, p.recovery)
    pose = np.array([3.0, 3.0, 0.2])
    v, w, kind = shim.command(pose, 0.0, _path_west(), _local([], pose, p))
    assert kind == "rotate" and v == 0.0 and w > 0  # the short way round: left
    assert (
        w <= p.dwa.acc_lim_theta / p.dwa.controller_frequency + 1e-9
    )  # from rest: one step's accel
    pose[2] = math.pi - 0.9  # 0.9 rad off: above the release angle, it keeps turning
    assert shim.command(pose, 0.25, _path_west(), _local([], pose, p))[2] == "rotate"
    pose[2] = math.pi - 0.4  # below shim_release (0.5 rad): the DWA takes over
    assert shim.command(pose, 0.5, _path_west(), _local([], pose, p)) is None


def test_boxed_in_it_backs_out_until_it_can_turn():
    # a 0.56 m wide dead-end slot open to the -x side, the robot in it facing its +x end; the
    # path leads out of the slot's open end behind the robot: no turn fits in the slot
    p = ExploreParams()
    walls = np.concatenate(
        [_segment(1.0, 2.72, 3.45, 2.72), _segment(1.0, 3.28, 3.45, 3.28),
         _segment(3.45, 2.72, 3.45, 3.28)]
    )  # fmt: skip
    x = np.array([3.0, 3.0, 0.0])
    shim = HeadingShim(p.dwa, p.costmap, p.recovery)
    kinds = _until_rotate(
        shim, x, lambda: (_path_west(x[0] - 0.3), _local(walls, x, p)), walls, steps=200
    )
    assert kinds[0] == "reverse" and kinds[-1] == "rotate"
    assert x[0] < 1.2  # it backed out of the slot before it could turn
    assert shim.n_reversals == len(kinds) - 1


def test_a_turn_under_way_keeps_its_direction_when_the_path_is_about_behind():
    # lab_a_furnitures: with the path about behind, the heading crossing the angle opposite
    # the path flipped "the short way round" every other period, and the robot swung back
    # and forth among chair legs for minutes
    p = ExploreParams()
    shim = HeadingShim(p.dwa, p.costmap, p.recovery)
    pose = np.array([3.0, 3.0, 0.14])  # the path (west) 3.0 rad to the left
    assert shim.command(pose, 0.0, _path_west(), _local([], pose, p))[1] > 0
    pose[2] = -0.04  # now 3.10 rad to the right, 3.18 to the left: keep turning left
    assert shim.command(pose, 0.3, _path_west(), _local([], pose, p))[1] > 0
    fresh = HeadingShim(
        p.dwa, p.costmap, p.recovery
    )  # a robot that was not turning takes the short way: right
    assert fresh.command(pose, 0.0, _path_west(), _local([], pose, p))[1] < 0


def test_boxed_in_among_table_legs_it_backs_out_the_way_it_came_not_into_a_slot():
    # Captured from office_b_furnitures (graph SLAM, seed 3) at 12.9 s: the SLAM map around
    # the robot, the local costmap's laser marks, the robot's pose and its plan. The robot
    # drove north into a 0.6 m gap between table legs (west) and a cabinet (north-east); the
    # plan now leads back south-east, and no turn fits. Backing half a second ends nearer the
    # legs than a forward right turn does, so the shim used to creep forwards, turning, into
    # the slot between leg and cabinet, where the robot could neither turn nor leave: it
    # shuffled 3 cm back and forth until `stuck` (here: no turn within 10 s). Backing out
    # the way it came reaches room to turn.
    p = ExploreParams()
    data = np.load(Path(__file__).parents[2] / "data" / "office_b_furnitures_shim_trap.npz")
    q = data["prob"]
    prob = np.where(q == 255, np.nan, q / 250.0).astype(np.float32)
    res = float(data["resolution"])
    costmap = GlobalCostmap(p.costmap, p.doors.door_align)
    costmap.update(prob, res, tuple(data["origin"]))
    occ = np.argwhere(prob > p.costmap.occupied_thresh)  # (row, col) of the map's obstacle cells
    occ_xy = data["origin"] + (occ[:, ::-1] + 0.5) * res
    x = data["pose"].astype(float).copy()
    path = data["path"].astype(float)
    shim = HeadingShim(p.dwa, p.costmap, p.recovery)
    local = LocalCostmap(p.costmap, p.dwa, res)
    local.add_points(0.0, data["marks"].astype(float))

    def sense():
        local.build(x[0], x[1], costmap, x[2])
        return path, local

    kinds = _until_rotate(shim, x, sense, occ_xy, steps=100)  # 10 s
    assert kinds[0] == "reverse"  # out the way it came
    assert kinds[-1] == "rotate" and len(kinds) < 50  # room to turn within 5 s
    assert x[1] < data["pose"][1]  # south of where it was boxed in, not up in the slot
