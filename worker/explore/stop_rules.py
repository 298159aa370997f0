"""Stop rules of the exploration loop (one interface), and the thesis's map-snapshot MSE."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy import ndimage

from worker.evaluate.coverage import align_map_to_world
from worker.explore.params import StopParams
from worker.status import RunOutcome, RunReason

Outcome = RunOutcome  # completed | failed
Reason = RunReason  # completed: no_frontier, map_unchanged; failed: the others

# map_saver's grey levels: the thesis compared the saved map images pixel by pixel
_OCCUPIED, _FREE, _UNKNOWN = 0, 254, 205


def map_image(prob: np.ndarray, occ_thresh: float) -> np.ndarray:
    """`(H, W) uint8` map_saver levels (0 occupied, 254 free, 205 unknown), bottom row first."""
    img = np.full(prob.shape, _UNKNOWN, dtype=np.uint8)
    known = ~np.isnan(prob)
    img[known] = np.where(prob[known] > occ_thresh, _OCCUPIED, _FREE)
    return img


def _common_extent(a: np.ndarray, a_origin, b: np.ndarray, b_origin, resolution: float):
    """Two map images (bottom row first, lower-left corner at `*_origin` [m]) placed on their
    common extent; the part only one covers is unknown in the other. `(H, W) uint8` each."""
    ax, ay = (int(round(v / resolution)) for v in np.asarray(a_origin)[:2])
    bx, by = (int(round(v / resolution)) for v in np.asarray(b_origin)[:2])
    x0, y0 = min(ax, bx), min(ay, by)
    x1 = max(ax + a.shape[1], bx + b.shape[1])
    y1 = max(ay + a.shape[0], by + b.shape[0])
    ca = np.full((y1 - y0, x1 - x0), _UNKNOWN, dtype=np.uint8)
    cb = ca.copy()
    ca[ay - y0 : ay - y0 + a.shape[0], ax - x0 : ax - x0 + a.shape[1]] = a
    cb[by - y0 : by - y0 + b.shape[0], bx - x0 : bx - x0 + b.shape[1]] = b
    return ca, cb


def snapshot_mse(a: np.ndarray, a_origin, b: np.ndarray, b_origin, resolution: float) -> float:
    """The thesis's measure: mean squared pixel difference of two map images placed on their
    common extent.

    a, b: (H, W) uint8 images (bottom row first) with the world position of their lower-left
    corner; both share `resolution`. The part only one of them covers counts as unknown in
    the other, as a map that grew shows new pixels against the old image's background.
    """
    ca, cb = _common_extent(a, a_origin, b, b_origin, resolution)
    return float(np.mean((ca.astype(np.float32) - cb) ** 2))


@dataclass(frozen=True)
class SnapshotChange:
    """How much a map changed between two snapshots.

    changed_m2 [m^2]: cells whose class (free / occupied / unknown) changed and whose change
    is not a boundary moved by at most `tolerance` cells (the new class is not within that
    many cells in the old image, or the old class not within them in the new one).
    share [-]: changed_m2 over the area known (free or occupied) in either snapshot.
    mse [-]: the thesis's pixel MSE over all pixels of the common extent (map_saver levels).
    known_m2 [m^2]: that known area.
    """

    changed_m2: float
    share: float
    mse: float
    known_m2: float = 0.0


_CLASSES = (_OCCUPIED, _FREE, _UNKNOWN)


def snapshot_change(
    a: np.ndarray, a_origin, b: np.ndarray, b_origin, resolution: float, tolerance: int
) -> SnapshotChange:
    """The change from snapshot a to snapshot b (map images as `snapshot_mse` takes them).

    A wall the SLAM map draws a cell further out, a frontier that advanced by a cell: such
    jitter is not the map changing, so a cell counts only when its new class is absent from
    the old image within `tolerance` cells (8-neighbourhood), or its old class absent from
    the new one. tolerance 0 counts every changed cell.
    """
    ca, cb = _common_extent(a, a_origin, b, b_origin, resolution)
    mse = float(np.mean((ca.astype(np.float32) - cb) ** 2))
    changed = ca != cb
    if tolerance > 0 and changed.any():
        square = np.ones((3, 3), dtype=bool)
        explained_a = np.zeros_like(changed)  # b's class occurs near the cell in a
        explained_b = np.zeros_like(changed)  # a's class occurs near the cell in b
        for k in _CLASSES:
            near_a = ndimage.binary_dilation(ca == k, square, iterations=tolerance)
            near_b = ndimage.binary_dilation(cb == k, square, iterations=tolerance)
            explained_a |= (cb == k) & near_a
            explained_b |= (ca == k) & near_b
        changed &= ~(explained_a & explained_b)
    n_known = np.count_nonzero((ca != _UNKNOWN) | (cb != _UNKNOWN))
    n_changed = int(np.count_nonzero(changed))
    share = n_changed / n_known if n_known else math.inf  # nothing known: not unchanged
    cell_m2 = resolution * resolution
    return SnapshotChange(n_changed * cell_m2, share, mse, n_known * cell_m2)


class SnapshotRule:
    """Takes a map snapshot every `period` s; fires when two consecutive differ by little.

    measure "changed_share" (the default): less than `change` of the known map changed
    class beyond `tolerance` cells (`snapshot_change`); "mse": the thesis's pixel MSE below
    `mse` (`snapshot_mse`).
    """

    def __init__(
        self,
        period: float,
        mse: float,
        measure: str = "changed_share",
        change: float = 0.01,
        tolerance: int = 1,
    ):
        self.period = period
        self.mse = mse
        self.measure = measure
        self.change = change
        self.tolerance = tolerance
        self.next_t = period
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self.last: SnapshotChange | None = None

    @property
    def last_mse(self) -> float:
        return math.nan if self.last is None else self.last.mse

    def due(self, t: float) -> bool:
        return t >= self.next_t - 1e-9

    def check(self, t: float, prob: np.ndarray, origin, resolution: float, occ_thresh: float):
        """Take the snapshot due at t; True when it differs from the previous by little."""
        self.next_t += self.period
        img = map_image(prob, occ_thresh)
        origin = np.asarray(origin, dtype=float)[:2].copy()
        last, self._last = self._last, (img, origin)
        if last is None:
            return False
        self.last = c = snapshot_change(last[0], last[1], img, origin, resolution, self.tolerance)
        if self.measure == "mse":
            return c.mse < self.mse
        return c.share < self.change

    def describe(self) -> str:
        """The last comparison, in one line."""
        c = self.last
        if c is None:
            return f"map snapshots {self.period:g} s apart"
        return (
            f"map snapshots {self.period:g} s apart: {100 * c.share:.2f} % of the known map "
            f"changed ({c.changed_m2:.1f} m^2), MSE {c.mse:.2f}"
        )


@dataclass(frozen=True)
class StopReason:
    """Why a run ends: the reason and one human-readable line."""

    reason: Reason
    detail: str

    @property
    def outcome(self) -> Outcome:
        return RunReason(self.reason).outcome


@dataclass(frozen=True)
class LoopState:
    """What the stop rules see after one control period. The harness may look at the ground
    truth (pose_gt, the simulator's collisions); the robot may not."""

    t: float  # [s] simulated time
    dt: float  # [s] control period
    pose_gt: np.ndarray  # (3,) [x, y, theta] world frame
    pose_est: np.ndarray  # (3,) [x, y, theta] SLAM map frame
    status: str  # the navigation stack's, this period
    goal_failures: int  # goals given up in a row
    collisions: Sequence  # the simulator's collisions so far (worker.sim Collision)
    occupancy: Callable[[], object]  # the current SLAM map (OccupancyGrid), read on demand
    # [s] when the navigation stack chose the frontier goal it pursues (None: no goal)
    goal_t0: float | None = None


class StopRule(Protocol):
    """One stop rule: asked once per control period, in order, until one fires."""

    def check(self, s: LoopState) -> StopReason | None: ...


class CollisionRule:
    """failed, collision: the simulator reports a contact (the first since the start)."""

    def __init__(self, n_before: int):
        self.n_before = n_before  # collisions the simulator had when the run began

    def check(self, s: LoopState) -> StopReason | None:
        if len(s.collisions) <= self.n_before:
            return None
        c = s.collisions[self.n_before]
        return StopReason(
            RunReason.COLLISION, f"hit an obstacle at t={c.t:.1f} s, ({c.x:.2f}, {c.y:.2f})"
        )


class DivergenceRule:
    """failed, slam_diverged: the SLAM pose, mapped into the world as at the start, is more
    than `limit` [m] from the ground truth."""

    def __init__(self, limit: float):
        self.limit = limit
        self.T0: np.ndarray | None = None  # (3,) T_world_map from the first period

    def check(self, s: LoopState) -> StopReason | None:
        if self.T0 is None:
            self.T0 = align_map_to_world(s.pose_est[None, :], s.pose_gt[None, :])
        if _pose_error(self.T0, s.pose_est, s.pose_gt) <= self.limit:
            return None
        return StopReason(
            RunReason.SLAM_DIVERGED, f"SLAM pose more than {self.limit:g} m off at t={s.t:.1f} s"
        )


class GoalFailuresRule:
    """failed, stuck: `limit` goals given up in a row."""

    def __init__(self, limit: int):
        self.limit = limit

    def check(self, s: LoopState) -> StopReason | None:
        if s.goal_failures < self.limit:
            return None
        return StopReason(RunReason.STUCK, f"{self.limit} goals given up in a row")


class NoFrontierRule:
    """completed, no_frontier: no reachable frontier for `hold` [s] (a transient gap in the
    map must not end the run)."""

    def __init__(self, hold: float):
        self.hold = hold
        self.since: float | None = None  # [s] no frontier since

    def check(self, s: LoopState) -> StopReason | None:
        if s.status != "no_frontier":
            self.since = None
        elif self.since is None:
            self.since = s.t
        elif s.t - self.since >= self.hold - 1e-9:
            return StopReason(RunReason.NO_FRONTIER, "no reachable frontier left")
        return None


class NotMovingRule:
    """failed, stuck: the robot (ground truth) moved less than `distance` [m] in `timeout` [s]."""

    def __init__(self, start_xy: np.ndarray, distance: float, timeout: float):
        self.distance = distance
        self.timeout = timeout
        self.ref_xy = np.array(start_xy[:2], dtype=float)  # (2,) [m] where it last was
        self.ref_t = 0.0  # [s] when

    def check(self, s: LoopState) -> StopReason | None:
        if np.hypot(*(s.pose_gt[:2] - self.ref_xy)) > self.distance:
            self.ref_xy, self.ref_t = s.pose_gt[:2].copy(), s.t
        elif s.t - self.ref_t >= self.timeout:
            return StopReason(
                RunReason.STUCK, f"moved less than {self.distance:g} m in {self.timeout:g} s"
            )
        return None


class MapUnchangedRule:
    """completed, map_unchanged (thesis g, e): two map snapshots `period` [s] apart differ by
    little (SnapshotRule's measures).

    With holds the rule does not fire while the robot is on its way to a frontier it chose
    since the earlier snapshot: a goal chosen in the last period has not been tried yet, so it
    waits for the next snapshot. A run has `holds` such waits (explore.stop.snapshot_holds, 1
    by default), and one more for every `holds_area` [m^2] of the map known at the snapshot
    (snapshot_holds_area; 0: none). The share of the known map a period must change grows
    with the building, and so does the number of long drives to a far wing, each a period
    that changes less than that share (the generated 200 m x 100 m warehouse, oracle: one
    wait ended it at 5,100 s with 5 % of its floor unseen)."""

    def __init__(self, period: float, mse: float, holds: int = 0, holds_area: float = 0.0,
                 **measure):  # fmt: skip
        self.snapshots = SnapshotRule(period, mse, **measure)
        self.holds = holds  # waits a run has whatever its size
        self.holds_area = holds_area
        self.held = 0  # times the rule waited for a goal

    def allowed(self, known_m2: float) -> int:
        """The waits a run has with `known_m2` [m^2] of its map known."""
        if self.holds_area <= 0:
            return self.holds
        return self.holds + int(known_m2 // self.holds_area)

    def check(self, s: LoopState) -> StopReason | None:
        rule = self.snapshots
        if not rule.due(s.t):
            return None
        grid = s.occupancy()
        if not rule.check(s.t, grid.prob, grid.origin, grid.resolution, grid.occ_thresh):
            return None
        fresh = s.goal_t0 is not None and s.goal_t0 > s.t - rule.period
        if fresh and self.held < self.allowed(rule.last.known_m2):
            self.held += 1
            return None
        detail = rule.describe()
        if self.held:
            detail += f" (waited {self.held} time(s) for a goal chosen since the last snapshot)"
        return StopReason(RunReason.MAP_UNCHANGED, detail)


class TimeLimitRule:
    """failed, time_limit (thesis m): the next period would pass `limit` [s] of simulated time."""

    def __init__(self, limit: float):
        self.limit = limit

    def check(self, s: LoopState) -> StopReason | None:
        if s.t + s.dt <= self.limit + 1e-9:
            return None
        return StopReason(RunReason.TIME_LIMIT, f"time limit {self.limit:g} s reached")


def default_rules(
    p: StopParams, time_limit: float, start_xy: np.ndarray, n_collisions: int
) -> list[StopRule]:
    """The loop's stop rules in the order they are asked: the first to fire ends the run;
    time_limit [s]: ExploreParams.time_limit (m)."""
    return [
        CollisionRule(n_collisions),
        DivergenceRule(p.slam_divergence),
        GoalFailuresRule(p.max_goal_failures),
        NoFrontierRule(p.no_frontier_time),
        NotMovingRule(start_xy, p.stuck_distance, p.stuck_timeout),
        MapUnchangedRule(
            p.snapshot_period,
            p.snapshot_mse,
            holds=p.snapshot_holds,
            holds_area=p.snapshot_holds_area,
            measure=p.snapshot_measure,
            change=p.snapshot_change,
            tolerance=p.snapshot_tolerance,
        ),  # fmt: skip
        TimeLimitRule(time_limit),
    ]


def first_stop(rules: Sequence[StopRule], s: LoopState) -> StopReason | None:
    """Ask the rules in order; the first answer, or None when none fires."""
    for rule in rules:
        stop = rule.check(s)
        if stop is not None:
            return stop
    return None


def _pose_error(T0: np.ndarray, pose_est: np.ndarray, pose_gt: np.ndarray) -> float:
    """[m] distance between the ground truth and the estimate mapped by T0 into the world."""
    c, s = math.cos(T0[2]), math.sin(T0[2])
    x = T0[0] + c * pose_est[0] - s * pose_est[1]
    y = T0[1] + s * pose_est[0] + c * pose_est[1]
    return math.hypot(x - pose_gt[0], y - pose_gt[1])
