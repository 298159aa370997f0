"""DWA local planner (base_local_planner TrajectoryPlanner, dwa: true) following a global path."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from worker.evaluate.se2_scalar import wrap_fold as wrap_angle
from worker.explore import dwa_kernels as dk
from worker.explore.costmap import LocalCostmap
from worker.explore.params import CostmapParams, DwaParams


def drive(x: float, y: float, th: float, v: float, w: float, duration: float, n: int):
    """The pose after driving (v, w) for `duration` [s] from (x, y, th), in n Euler steps."""
    dt = duration / n
    for _ in range(n):
        x += v * math.cos(th) * dt
        y += v * math.sin(th) * dt
        th += w * dt
    return x, y, th


@dataclass(frozen=True)
class Command:
    """One controller output."""

    v: float  # [m/s]
    w: float  # [rad/s]
    legal: bool  # False: no legal trajectory, the robot is told to stop
    # "forward", "rotate", "escape"; "align" turning at the goal, "aligned" goal reached; "none"
    kind: str


class DwaPlanner:
    """Scores forward-simulated (v, w) samples against the local costmap and the global path."""

    def __init__(self, params: DwaParams, costmap: CostmapParams):
        """costmap: the footprint's settings (footprint_half_m, footprint_padding)."""
        self.params = params
        self.half_m = costmap.footprint_half_m  # [m] the bare footprint's half side
        p = params
        prm = np.zeros(dk.N_PARAMS)
        prm[dk.P_DT] = 1.0 / p.controller_frequency
        prm[dk.P_MAX_VX] = p.max_vel_x
        prm[dk.P_MIN_VX] = p.min_vel_x
        prm[dk.P_MAX_VTH] = p.max_vel_theta
        prm[dk.P_MIN_INPLACE_VTH] = p.min_in_place_vel_theta
        prm[dk.P_ACC_X] = p.acc_lim_x
        prm[dk.P_ACC_TH] = p.acc_lim_theta
        prm[dk.P_SIM_TIME] = p.sim_time
        prm[dk.P_SIM_GRAN] = p.sim_granularity
        prm[dk.P_ANG_GRAN] = p.angular_sim_granularity
        prm[dk.P_PDIST] = p.pdist_scale
        prm[dk.P_GDIST] = p.gdist_scale
        prm[dk.P_OCCDIST] = p.occdist_scale
        prm[dk.P_LOOKAHEAD] = p.heading_lookahead
        prm[dk.P_HALF] = costmap.footprint_half_m + costmap.footprint_padding
        prm[dk.P_CIRC] = costmap.footprint_half_m * math.sqrt(2.0)
        prm[dk.P_ESCAPE_VX] = p.escape_vel
        prm[dk.P_HALF_RAW] = costmap.footprint_half_m
        self.prm = prm
        self._prm_unpadded = prm.copy()
        self.path_xy: np.ndarray | None = None
        self.local_goal_xy: np.ndarray | None = None
        self._rotating_left = self._rotating_right = False
        self._stuck_left = self._stuck_right = False
        self._prev_xy = (0.0, 0.0)
        self._escape_from: tuple[float, float, float] | None = None
        self._dist = np.zeros((2, 0, 0), dtype=np.float32)  # path / goal distance buffers
        # [m] the farthest from the robot a scored trajectory's point or the heading
        # look-ahead can be: the distance maps are needed that far only
        fastest = max(abs(p.max_vel_x), abs(p.min_vel_x), abs(p.escape_vel))
        self._reach = max(fastest * p.sim_time, p.heading_lookahead)
        self._queue = np.zeros(0, dtype=np.int64)

    def set_plan(self, path_xy: np.ndarray | None) -> None:
        """New global path `(K, 2) [x, y]` in the map frame (None: no path)."""
        self.path_xy = None if path_xy is None or len(path_xy) == 0 else np.asarray(path_xy)
        if self.path_xy is None:
            self._escape_from = None

    def command(
        self,
        pose: np.ndarray,
        v0: float,
        w0: float,
        local: LocalCostmap,
        goal_yaw: float | None,
        no_forward: bool = False,
    ) -> Command:
        """Velocity for this control period from pose `(3,)` [x, y, theta] and current (v0, w0).

        Within xy_goal_tolerance of the path's end the robot only turns towards `goal_yaw`
        (when given), as move_base does before declaring the goal reached. no_forward: only
        turning in place or backing off (the safety controller forbids going on).
        """
        if self.path_xy is None:
            return Command(0.0, 0.0, False, "none")
        p = self.params
        goal = self.path_xy[-1]
        if math.hypot(goal[0] - pose[0], goal[1] - pose[1]) <= p.xy_goal_tolerance:
            return self._align(pose, w0, local, goal_yaw)
        seeds, goal_cell = self._local_plan(pose, local)
        if seeds is None:
            return Command(0.0, 0.0, False, "none")
        # meter_scoring as TrajectoryPlannerROS does it: every weight times the resolution,
        # distances counted in cells, so distances in metres and the cost weight x resolution
        self.prm[dk.P_OCCDIST] = p.occdist_scale * local.resolution
        self._prm_unpadded[:] = self.prm
        self._prm_unpadded[dk.P_HALF] = self.half_m
        path_dist, goal_dist = self._distances(pose, local, seeds, goal_cell)
        goal_gap = math.hypot(goal[0] - pose[0], goal[1] - pose[1])
        vx, vth, kind = self._best(pose, v0, w0, local, goal_gap, path_dist, goal_dist, no_forward)
        self._track_oscillation(pose, kind, vth)
        if kind < 0:
            return Command(0.0, 0.0, False, "none")
        return Command(float(vx), float(vth), True, ("forward", "rotate", "escape")[kind])

    def command_or_scans_only(
        self, pose: np.ndarray, v0: float, w0: float, local: LocalCostmap, costmap
    ) -> Command:
        """`command` towards the plan's end (no heading asked); with nothing legal, its
        command on the scans alone (`local` rebuilt without the map from `costmap`, the
        GlobalCostmap)."""
        # Frontier goals carry no heading requirement: with a 270 degree laser the robot sees
        # the frontier on arrival, and turning in place in a doorway is how robots got stuck.
        cmd = self.command(pose, v0, w0, local, None)
        if not cmd.legal:
            # the map's obstacles may sit a cell nearer than the real ones (rounded hits):
            # with nothing legal, trust the scans alone, as the thesis's local costmap did
            local.build(pose[0], pose[1], costmap, pose[2], use_map=False)
            cmd = self.command(pose, v0, w0, local, None)
            if cmd.kind in ("escape", "rotate"):
                # not blind: backing up or turning sweeps what the laser does not see
                cmd = Command(0.0, 0.0, False, "none")
        return cmd

    def _distances(self, pose, local: LocalCostmap, seeds, goal_cell):
        """The distance maps `(n, n)` [m] to the path (`seeds`) and to the local goal, filled
        only where a trajectory or the heading look-ahead can reach."""
        n = local.cost.shape[0]
        if self._dist.shape[1:] != local.cost.shape:
            self._dist = np.empty((2, n, n), dtype=np.float32)
            self._queue = np.empty(n * n, dtype=np.int64)
        path_dist, goal_dist = self._dist[0], self._dist[1]
        cy = int(math.floor((pose[1] - local.origin[1]) / local.resolution))
        cx = int(math.floor((pose[0] - local.origin[0]) / local.resolution))
        r = int(math.ceil(self._reach / local.resolution)) + 2
        dk.wavefront_into(seeds, local.cost, local.resolution, path_dist, self._queue, cy, cx, r)
        dk.wavefront_into(
            goal_cell, local.cost, local.resolution, goal_dist, self._queue, cy, cx, r
        )
        return path_dist, goal_dist

    def _best(self, pose, v0, w0, local: LocalCostmap, goal_gap, path_dist, goal_dist, no_forward):
        """(vx, vth, kind) of the best trajectory: with the padded footprint, then the exact
        one, then with the oscillation flags cleared; kind < 0: nothing legal."""
        p = self.params
        passes = [(self.prm, False), (self._prm_unpadded, True)]
        if self._stuck_left or self._stuck_right:
            passes.append((None, True))  # nothing legal: the oscillation flags give way too
        for prm, last in passes:
            if prm is None:
                prm = self._prm_unpadded
                self._stuck_left = self._stuck_right = False
            # the padding is a preference: with nothing legal (robot wedged in a doorway, say)
            # the exact footprint decides, before backing off is tried
            vx, vth, _, kind = dk.best_command(
                float(pose[0]), float(pose[1]), float(pose[2]), float(v0), float(w0), goal_gap,
                self._stuck_left, self._stuck_right, no_forward or self._escape_from is not None,
                p.vx_samples, p.vtheta_samples,
                local.lethal, local.near, local.inner, local.cost, path_dist, goal_dist,
                float(local.origin[0]), float(local.origin[1]), local.resolution, prm, last,
            )  # fmt: skip
            if kind >= 0:
                break
        return vx, vth, kind

    def _track_oscillation(self, pose, kind: int, vth: float) -> None:
        """TrajectoryPlanner's oscillation flags: an in-place turn one way after one the other
        way since the robot last moved blocks the first way (left = positive vth), until the
        robot travels oscillation_reset_dist, so it cannot dither left-right on the spot but
        may keep turning the same way as long as it needs; after backing off, no forward
        motion until escape_reset_dist / escape_reset_theta from there."""
        p = self.params
        if kind == 2 and self._escape_from is None:
            self._escape_from = (float(pose[0]), float(pose[1]), float(pose[2]))
        if self._escape_from is not None:
            ex, ey, eth = self._escape_from
            if (
                math.hypot(pose[0] - ex, pose[1] - ey) > p.escape_reset_dist
                or abs(wrap_angle(pose[2] - eth)) > p.escape_reset_theta
            ):
                self._escape_from = None
        if self._stuck_left and self._stuck_right:
            # both ways flagged: base_local_planner would leave only the back-off; let the
            # robot turn again rather than shuffle forwards and backwards on the spot
            self._stuck_left = self._stuck_right = False
            self._rotating_left = self._rotating_right = False
        if kind == 1:
            if vth < 0:
                self._stuck_left |= self._rotating_left
                self._rotating_right = True
            else:
                self._stuck_right |= self._rotating_right
                self._rotating_left = True
            self._prev_xy = (float(pose[0]), float(pose[1]))
        moved = math.hypot(pose[0] - self._prev_xy[0], pose[1] - self._prev_xy[1])
        if moved > self.params.oscillation_reset_dist:
            self._rotating_left = self._rotating_right = False
            self._stuck_left = self._stuck_right = False

    def goal_reached(self, pose: np.ndarray, goal_yaw: float | None) -> bool:
        """Within xy_goal_tolerance of the path's end and (if a yaw is given) yaw_goal_tolerance."""
        if self.path_xy is None:
            return False
        goal = self.path_xy[-1]
        if math.hypot(goal[0] - pose[0], goal[1] - pose[1]) > self.params.xy_goal_tolerance:
            return False
        return goal_yaw is None or abs(wrap_angle(goal_yaw - pose[2])) <= (
            self.params.yaw_goal_tolerance
        )

    def _align(self, pose, w0: float, local: LocalCostmap, goal_yaw: float | None) -> Command:
        p = self.params
        if goal_yaw is None:
            return Command(0.0, 0.0, True, "aligned")
        err = wrap_angle(goal_yaw - pose[2])
        if abs(err) <= p.yaw_goal_tolerance:
            return Command(0.0, 0.0, True, "aligned")
        # Proportional turn, at least min_in_place_vel, within what acc_lim_theta allows.
        w = max(p.min_in_place_vel_theta, min(p.max_vel_theta, abs(err)))
        w = math.copysign(w, err)
        dt = 1.0 / p.controller_frequency
        w = min(max(w, w0 - p.acc_lim_theta * dt), w0 + p.acc_lim_theta * dt)
        if not dk.rotation_legal(
            float(pose[0]), float(pose[1]), float(pose[2]), math.copysign(abs(w), err),
            local.lethal, local.near, local.inner, float(local.origin[0]), float(local.origin[1]),
            local.resolution, self.prm,
        ):  # fmt: skip
            return Command(0.0, 0.0, True, "aligned")  # turning would hit something: accept yaw
        return Command(0.0, float(w), True, "align")

    def _local_plan(self, pose, local: LocalCostmap):
        """Path cells inside the local window from the point nearest the robot; local goal cell."""
        path = self.path_xy
        d = np.hypot(path[:, 0] - pose[0], path[:, 1] - pose[1])
        i0 = int(np.argmin(d))
        rest = path[i0:]
        cx = np.floor((rest[:, 0] - local.origin[0]) / local.resolution).astype(np.int64)
        cy = np.floor((rest[:, 1] - local.origin[1]) / local.resolution).astype(np.int64)
        inside = (cx >= 1) & (cx < local.n - 1) & (cy >= 1) & (cy < local.n - 1)
        if not inside[0]:
            return None, None
        out = np.flatnonzero(~inside)
        k = int(out[0]) if out.size else len(rest)
        seeds = np.column_stack((cy[:k], cx[:k]))
        self.local_goal_xy = rest[k - 1]
        return seeds, seeds[k - 1 : k].copy()
