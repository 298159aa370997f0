"""Stop rules: each on hand-made loop states, their order, and the thesis's snapshot MSE."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from tests.worker.explore.test_loop import _dead_end_world, _run
from worker.explore.flat_params import explore_params
from worker.explore.stop_rules import (
    CollisionRule,
    DivergenceRule,
    GoalFailuresRule,
    LoopState,
    MapUnchangedRule,
    NoFrontierRule,
    NotMovingRule,
    SnapshotRule,
    StopReason,
    TimeLimitRule,
    default_rules,
    first_stop,
    map_image,
    snapshot_change,
    snapshot_mse,
)


def test_map_image_uses_map_savers_grey_levels():
    prob = np.array([[np.nan, 0.1], [0.3, 0.25]], dtype=np.float32)
    np.testing.assert_array_equal(map_image(prob, 0.25), [[205, 254], [0, 254]])


def test_snapshot_mse_of_two_images_on_one_extent():
    a = np.array([[0, 254], [205, 205]], dtype=np.uint8)
    b = np.array([[254, 254], [205, 205]], dtype=np.uint8)
    # one pixel of four went from occupied to free: 254^2 / 4
    assert snapshot_mse(a, (0.0, 0.0), b, (0.0, 0.0), 0.05) == 254**2 / 4


def test_a_grown_map_counts_its_new_pixels_against_unknown():
    a = np.array([[254]], dtype=np.uint8)
    right = np.array([[254, 0]], dtype=np.uint8)  # grew by one occupied pixel to the right
    assert snapshot_mse(a, (0.0, 0.0), right, (0.0, 0.0), 0.05) == 205**2 / 2
    left = np.array([[0, 254]], dtype=np.uint8)  # the same pixel on the left: origin moved
    assert snapshot_mse(a, (0.0, 0.0), left, (-0.05, 0.0), 0.05) == 205**2 / 2
    # placed at the old origin instead: 254 -> 0 and unknown -> 254
    assert snapshot_mse(a, (0.0, 0.0), left, (0.0, 0.0), 0.05) == (254**2 + 49**2) / 2


def test_rule_takes_a_snapshot_every_period_and_fires_on_a_small_change():
    rule = SnapshotRule(period=300.0, mse=5.0, measure="mse")  # the thesis's rule
    prob = np.full((10, 10), 0.1, dtype=np.float32)
    assert not rule.due(299.9) and rule.due(300.0)
    assert not rule.check(300.0, prob, (0.0, 0.0), 0.05, 0.25)  # the first: nothing to compare
    assert not rule.due(599.9) and rule.due(600.0)
    changed = prob.copy()
    changed[0, 0] = 0.9  # 254^2 / 100 = 645 >= 5
    assert not rule.check(600.0, changed, (0.0, 0.0), 0.05, 0.25)
    assert rule.last_mse == pytest.approx(254**2 / 100)
    assert rule.check(900.0, changed, (0.0, 0.0), 0.05, 0.25)  # unchanged: 0 < 5
    assert rule.last_mse == 0.0


def _room(shape=(40, 40), wall_x=30):
    """A free room with a vertical wall (occupied column) at wall_x, unknown beyond it."""
    img = np.full(shape, 205, dtype=np.uint8)
    img[:, :wall_x] = 254
    img[:, wall_x] = 0
    return img


def test_a_wall_drawn_one_cell_further_out_is_not_a_change():
    a, b = _room(wall_x=30), _room(wall_x=31)
    c = snapshot_change(a, (0.0, 0.0), b, (0.0, 0.0), 0.05, tolerance=1)
    assert c.changed_m2 == 0.0 and c.share == 0.0
    # the thesis's MSE sees the 40 cells free -> ... each changed: 40 (254^2) + 40 (205^2)
    assert c.mse == pytest.approx((40 * 254**2 + 40 * 205**2) / 1600)
    # counted cell by cell (tolerance 0): the two changed columns, 80 cells of 0.0025 m^2
    c0 = snapshot_change(a, (0.0, 0.0), b, (0.0, 0.0), 0.05, tolerance=0)
    assert c0.changed_m2 == pytest.approx(80 * 0.0025)
    # known in either: 32 columns of 40 cells
    assert c0.share == pytest.approx(80 / (32 * 40))


def test_a_wall_moved_two_cells_and_new_free_space_count():
    a, b = _room(wall_x=20), _room(wall_x=22)
    c = snapshot_change(a, (0.0, 0.0), b, (0.0, 0.0), 0.05, tolerance=1)
    # a cell counts unless its new class is within one cell in a AND its old class within
    # one cell in b. Column 20 (0 -> 254): free at 19 in a, but occupied only at 22 in b
    # (2 off): counts. Column 21 (205 -> 254): free only at 19 in a (2 off): counts. Column
    # 22 (205 -> 0): occupied only at 20 in a (2 off): counts.
    assert c.changed_m2 == pytest.approx(3 * 40 * 0.0025)
    assert c.share == pytest.approx(3 * 40 / (23 * 40))


def test_a_map_that_grew_counts_its_new_area_past_the_first_cell():
    a = _room(wall_x=10)
    b = np.full((40, 50), 205, dtype=np.uint8)  # seen 10 cells further, extent grown right
    b[:, :20] = 254
    b[:, 20] = 0
    c = snapshot_change(a, (0.0, 0.0), b, (0.0, 0.0), 0.05, tolerance=1)
    # columns 10..20 changed. Column 10 (0 -> 254): b's nearest occupied is column 20:
    # counts. Columns 11..19 (205 -> 254): a's nearest free is column 9, 2 or more off:
    # count. Column 20 (205 -> 0): a's occupied is column 10: counts. 11 columns of 40 cells
    assert c.changed_m2 == pytest.approx(11 * 40 * 0.0025)
    assert c.share == pytest.approx(11 * 40 / (21 * 40))


def test_nothing_known_is_never_unchanged():
    a = np.full((4, 4), 205, dtype=np.uint8)
    assert snapshot_change(a, (0.0, 0.0), a, (0.0, 0.0), 0.05, 1).share == float("inf")


def test_the_default_rule_fires_on_the_share_of_the_known_map():
    rule = SnapshotRule(period=300.0, mse=5.0)  # default: changed_share < 0.01, 1 cell
    prob = np.full((20, 20), 0.1, dtype=np.float32)  # 400 known free cells
    assert not rule.check(300.0, prob, (0.0, 0.0), 0.05, 0.25)
    moved = prob.copy()
    # a 4 x 4 obstacle appears where the old map had no obstacle near: all 16 cells count
    moved[5:9, 5:9] = 0.9
    assert not rule.check(600.0, moved, (0.0, 0.0), 0.05, 0.25)
    assert rule.last.share == pytest.approx(16 / 400)
    assert rule.last.changed_m2 == pytest.approx(16 * 0.0025)
    # a single cell that turns occupied is 1 cell of 400 (0.25 %): unchanged, though its MSE
    # 254^2 / 400 = 161 is far above the thesis's e = 5
    one = moved.copy()
    one[15, 15] = 0.9
    assert rule.check(900.0, one, (0.0, 0.0), 0.05, 0.25)
    assert rule.last.mse == pytest.approx(254**2 / 400)


def test_exploration_ends_when_the_rule_fires_incomplete_with_the_corridor_unseen():
    # a threshold no pair of snapshots can miss: the run ends at the second snapshot, 6 s
    # in, with the 7.8 m corridor (1.2 m wide, > 2 m^2) never seen: a done-rule that fired
    # early is incomplete, not completed
    result, _ = _run(_dead_end_world(), snapshot_period=3.0, snapshot_change=1e9, snapshot_holds=0)
    assert result.outcome == "incomplete" and result.reason == "map_unchanged"
    assert "never seen" in result.stop_detail
    assert abs(result.t[-1] - 6.0) < 0.15
    assert "of the known map changed" in result.stop_detail and "MSE" in result.stop_detail
    # oracle SLAM: the pose it drove on was the true one, so the loss is the navigation's
    assert result.stop_detail.endswith(
        "; at the end the SLAM pose was 0.00 m and 0.00 rad from the true one (paths aligned)"
    )
    # with one wait: the robot set off for a goal within those 6 s, so the rule waits for
    # the third snapshot, and says so
    result, _ = _run(_dead_end_world(), snapshot_period=3.0, snapshot_change=1e9, snapshot_holds=1)
    assert result.reason == "map_unchanged" and abs(result.t[-1] - 9.0) < 0.15
    assert "(waited 1 time(s) for a goal chosen since the last snapshot)" in result.stop_detail


def test_the_end_pose_error_is_the_aligned_estimate_against_the_truth():
    from worker.explore.loop import end_pose_error_line

    # T_world_map (1, 2, pi/2) takes the estimate (1, 0, 0) to (1, 3, pi/2); the truth is
    # (1, 3.5, pi/2 + 0.1): 0.5 m and 0.1 rad off
    line = end_pose_error_line(
        np.array([1.0, 2.0, np.pi / 2]), np.array([1.0, 0.0, 0.0]),
        np.array([1.0, 3.5, np.pi / 2 + 0.1]),
    )  # fmt: skip
    assert (
        line == "at the end the SLAM pose was 0.50 m and 0.10 rad from the true one (paths aligned)"
    )
    # headings compared across the +-pi seam: 3.1 and -3.1 rad are 0.08 rad apart
    line = end_pose_error_line(np.zeros(3), np.array([0.0, 0.0, 3.1]), np.array([0.0, 0.0, -3.1]))
    assert "0.08 rad" in line


def _state(t=0.0, pose_gt=(0.0, 0.0, 0.0), pose_est=None, status="driving", **kw):
    pose_gt = np.array(pose_gt, dtype=float)
    pose_est = pose_gt.copy() if pose_est is None else np.array(pose_est, dtype=float)
    fields = {"dt": 0.1, "goal_failures": 0, "collisions": [], "occupancy": None} | kw
    return LoopState(
        t, fields["dt"], pose_gt, pose_est, status, fields["goal_failures"],
        fields["collisions"], fields["occupancy"], fields.get("goal_t0"),
    )  # fmt: skip


def test_no_frontier_must_hold_for_its_whole_time():
    rule = NoFrontierRule(hold=1.0)
    assert rule.check(_state(0.0, status="no_frontier")) is None  # since 0.0
    assert rule.check(_state(0.9, status="no_frontier")) is None
    assert rule.check(_state(1.0, status="driving")) is None  # a frontier again: reset
    assert rule.check(_state(1.1, status="no_frontier")) is None  # since 1.1
    assert rule.check(_state(2.0, status="no_frontier")) is None  # 0.9 s
    stop = rule.check(_state(2.1, status="no_frontier"))  # 1.0 s
    assert stop == StopReason("no_frontier", "no reachable frontier left")
    assert stop.outcome == "completed"


def test_not_moving_counts_from_the_last_place_the_robot_left():
    rule = NotMovingRule(np.array([0.0, 0.0, 0.0]), distance=0.5, timeout=10.0)
    assert rule.check(_state(9.9, pose_gt=(0.4, 0.3, 0.0))) is None  # 0.5 m away: not more
    assert rule.check(_state(10.0, pose_gt=(0.3, 0.4, 0.0))) == StopReason(
        "stuck", "moved less than 0.5 m in 10 s"
    )
    rule = NotMovingRule(np.array([0.0, 0.0, 0.0]), distance=0.5, timeout=10.0)
    assert rule.check(_state(5.0, pose_gt=(0.6, 0.0, 0.0))) is None  # moved: the clock restarts
    assert rule.check(_state(14.9, pose_gt=(0.9, 0.0, 0.0))) is None
    assert rule.check(_state(15.0, pose_gt=(0.9, 0.0, 0.0))).reason == "stuck"


def test_time_limit_fires_when_the_next_period_would_pass_it():
    rule = TimeLimitRule(10.0)
    assert rule.check(_state(9.9)) is None  # 9.9 + 0.1 = 10: the last period is still run
    stop = rule.check(_state(10.0))
    assert stop == StopReason("time_limit", "time limit 10 s reached")
    assert stop.outcome == "failed"


def test_collision_rule_reports_the_first_new_contact():
    @dataclass
    class Hit:
        t: float
        x: float
        y: float

    rule = CollisionRule(n_before=1)
    old = [Hit(0.0, 9.0, 9.0)]
    assert rule.check(_state(1.0, collisions=old)) is None
    stop = rule.check(_state(2.0, collisions=[*old, Hit(1.94, 1.234, -0.5), Hit(2.0, 0, 0)]))
    assert stop == StopReason("collision", "hit an obstacle at t=1.9 s, (1.23, -0.50)")


def test_divergence_is_measured_in_the_frame_of_the_first_period():
    rule = DivergenceRule(limit=3.0)
    # the SLAM map frame: the world turned by 90 degrees and shifted by (1, 2)
    assert rule.check(_state(0.0, pose_gt=(1.0, 2.0, np.pi / 2), pose_est=(0, 0, 0))) is None
    # est (2, 0) in the map is (1, 4) in the world: 2.9 m from (1, 6.9)
    assert rule.check(_state(5.0, pose_gt=(1.0, 6.9, 0.0), pose_est=(2.0, 0.0, 0.0))) is None
    stop = rule.check(_state(6.0, pose_gt=(1.0, 7.1, 0.0), pose_est=(2.0, 0.0, 0.0)))
    assert stop == StopReason("slam_diverged", "SLAM pose more than 3 m off at t=6.0 s")


def test_goal_failures_rule():
    rule = GoalFailuresRule(limit=10)
    assert rule.check(_state(goal_failures=9)) is None
    assert rule.check(_state(goal_failures=10)) == StopReason("stuck", "10 goals given up in a row")


def test_map_unchanged_rule_reads_the_map_only_when_a_snapshot_is_due():
    reads = []

    @dataclass
    class Grid:
        prob: np.ndarray
        origin: tuple = (0.0, 0.0)
        resolution: float = 0.05
        occ_thresh: float = 0.25

    def occupancy():
        reads.append(1)
        return Grid(np.full((4, 4), 0.1, dtype=np.float32))

    rule = MapUnchangedRule(period=300.0, mse=5.0)
    assert rule.check(_state(299.9, occupancy=occupancy)) is None and not reads
    assert rule.check(_state(300.0, occupancy=occupancy)) is None and len(reads) == 1
    stop = rule.check(_state(600.0, occupancy=occupancy))  # the same map: nothing changed
    detail = "map snapshots 300 s apart: 0.00 % of the known map changed (0.0 m^2), MSE 0.00"
    assert stop == StopReason("map_unchanged", detail)
    assert stop.outcome == "completed"


def test_map_unchanged_waits_once_for_a_goal_chosen_since_the_last_snapshot():
    @dataclass
    class Grid:
        prob: np.ndarray = field(default_factory=lambda: np.full((4, 4), 0.1, np.float32))
        origin: tuple = (0.0, 0.0)
        resolution: float = 0.05
        occ_thresh: float = 0.25

    def at(t, goal_t0):
        return _state(t, occupancy=Grid, goal_t0=goal_t0)

    rule = MapUnchangedRule(period=300.0, mse=5.0, holds=1)
    assert rule.check(at(300.0, None)) is None  # the first snapshot
    # the same map, but the robot set off at 450 s for a frontier: not tried yet, wait
    assert rule.check(at(600.0, 450.0)) is None
    # still the same map at 900 s; the goal of 850 s would be fresh too, but the one wait
    # the run had is used
    stop = rule.check(at(900.0, 850.0))
    assert stop is not None and stop.reason == "map_unchanged"
    assert stop.detail.endswith("(waited 1 time(s) for a goal chosen since the last snapshot)")
    # a goal chosen before the earlier snapshot (tried for a whole period) or none: no wait
    for goal_t0 in (300.0, None):
        rule = MapUnchangedRule(period=300.0, mse=5.0, holds=1)
        rule.check(at(300.0, None))
        assert rule.check(at(600.0, goal_t0)).reason == "map_unchanged"
    rule = MapUnchangedRule(period=300.0, mse=5.0, holds=0)  # off
    rule.check(at(300.0, None))
    assert rule.check(at(600.0, 450.0)).reason == "map_unchanged"


def test_map_unchanged_waits_once_more_for_every_holds_area_of_the_known_map():
    @dataclass
    class Grid:  # 20 x 10 known cells of 0.5 m: 50 m^2
        prob: np.ndarray = field(default_factory=lambda: np.full((10, 20), 0.1, np.float32))
        origin: tuple = (0.0, 0.0)
        resolution: float = 0.5
        occ_thresh: float = 0.25

    def waits(holds, holds_area):
        """How many snapshots in a row, each with a goal chosen since the one before, the rule
        lets pass before it fires."""
        rule = MapUnchangedRule(period=300.0, mse=5.0, holds=holds, holds_area=holds_area)
        rule.check(_state(300.0, occupancy=Grid))
        for k in range(1, 20):
            t = 300.0 * (k + 1)
            stop = rule.check(_state(t, occupancy=Grid, goal_t0=t - 100.0))
            if stop is not None:
                assert stop.detail.endswith(f"(waited {k - 1} time(s) for a goal chosen "
                                            "since the last snapshot)") or k == 1  # fmt: skip
                return k - 1
        return None

    assert waits(1, 0.0) == 1  # off: the run's one wait
    assert waits(1, 50.0) == 2  # 50 m^2 known: one more
    assert waits(1, 50.0001) == 1  # not quite a whole holds_area
    assert waits(1, 12.0) == 5  # 50 // 12 = 4 more
    assert waits(0, 25.0) == 2  # the waits for the area alone
    assert waits(0, 0.0) == 0


def test_rules_are_asked_in_order_and_the_first_answer_wins():
    @dataclass
    class Hit:
        t: float = 1.0
        x: float = 0.0
        y: float = 0.0

    p = explore_params(no_frontier_time=0.1, max_goal_failures=2)
    rules = default_rules(p.stop, p.time_limit, np.zeros(3), n_collisions=0)
    assert first_stop(rules, _state(0.0, status="no_frontier")) is None
    # no frontier for 0.1 s, two goals given up and a collision, all at once: the collision
    s = _state(0.1, status="no_frontier", goal_failures=2, collisions=[Hit()])
    assert first_stop(rules, s).reason == "collision"
    rules = default_rules(p.stop, p.time_limit, np.zeros(3), n_collisions=0)
    first_stop(rules, _state(0.0, status="no_frontier"))
    s = _state(0.1, status="no_frontier", goal_failures=2)
    assert first_stop(rules, s) == StopReason("stuck", "2 goals given up in a row")
