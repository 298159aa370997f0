"""The navigator's state machine: its first states by hand, and a whole run's transitions."""

from __future__ import annotations

import numpy as np

from tests.worker.explore.test_loop import _box, _cells
from worker.explore.flat_params import explore_params
from worker.explore.loop import Exploration
from worker.explore.nav_state import TRANSITIONS, NavState
from worker.explore.navigator import Navigator
from worker.explore.params import ExploreParams
from worker.sim.simulator import SimParams, Simulator
from worker.slam.params import SlamParams
from worker.slam.registry import make_slam
from worker.world.world import World

RES = 0.05
ANGLES = np.linspace(-2.35, 2.35, 541)
NO_HITS = np.full(541, 30.0)  # every beam at range_max


def test_without_a_map_the_navigator_waits():
    nav = Navigator(ExploreParams(), ANGLES, 30.0)
    cmd = nav.step(0.0, np.array([1.0, 1.0, 0.0]), 0.0, 0.0, NO_HITS)
    assert (cmd.v, cmd.w, cmd.status) == (0.0, 0.0, "planning")
    assert nav.state is NavState.WAITING and not nav.stats.transitions


def test_a_map_with_nothing_unknown_leaves_nothing_to_explore():
    nav = Navigator(ExploreParams(), ANGLES, 30.0)
    prob = np.full((60, 60), 0.05, dtype=np.float32)  # all known free, walled in
    prob[:2, :] = prob[-2:, :] = prob[:, :2] = prob[:, -2:] = 0.9
    nav.update_map(prob, RES, (0.0, 0.0), True)
    cmd = nav.step(0.0, np.array([1.5, 1.5, 0.0]), 0.0, 0.0, NO_HITS)
    assert (cmd.v, cmd.w, cmd.status) == (0.0, 0.0, "no_frontier")
    assert nav.state is NavState.EXHAUSTED and nav.goal is None
    S = NavState
    assert nav.stats.transitions == {(S.WAITING, S.IDLE): 1, (S.IDLE, S.EXHAUSTED): 1}


def test_a_frontier_in_view_becomes_the_goal_and_the_robot_drives_to_it():
    nav = Navigator(ExploreParams(), ANGLES, 30.0)
    prob = np.full((60, 100), np.nan, dtype=np.float32)
    prob[:, :50] = 0.05  # the left 2.5 m known free, the rest unknown: a frontier at x = 2.5
    nav.update_map(prob, RES, (0.0, 0.0), True)
    cmd = nav.step(0.0, np.array([1.0, 1.5, 0.0]), 0.0, 0.0, NO_HITS)
    assert nav.state is NavState.DRIVING
    assert nav.goal.frontier_xy[0] == 2.475  # the frontier column's cell centre
    assert nav.goal.goal_xy[0] < 2.5 and nav.path is not None
    assert cmd.v > 0.0 and cmd.status == "driving"  # straight ahead: no turning first
    S = NavState
    assert nav.stats.transitions == {(S.WAITING, S.IDLE): 1, (S.IDLE, S.DRIVING): 1}


def _scan_with_point(x: float, y: float) -> np.ndarray:
    """A scan seeing nothing but one point (x, y) in the robot frame."""
    ranges = NO_HITS.copy()
    k = int(round((np.arctan2(y, x) - ANGLES[0]) / (ANGLES[1] - ANGLES[0])))
    ranges[k] = np.hypot(x, y)
    return ranges


def test_an_obstacle_the_map_lacks_close_in_front_is_the_safety_controllers_then_driving_again():
    p = ExploreParams()
    nav = Navigator(p, ANGLES, 30.0)
    prob = np.full((60, 100), np.nan, dtype=np.float32)
    prob[:, :50] = 0.05  # a frontier straight ahead, as above
    nav.update_map(prob, RES, (0.0, 0.0), True)
    pose = np.array([1.0, 1.5, 0.0])
    assert nav.step(0.0, pose, 0.0, 0.0, NO_HITS).status == "driving"
    # something front-left, 0.18 m ahead of the footprint's front (half side 0.2 m) and 0.21 m
    # to the side, inside the 0.22 m band it sweeps: the DWA still drives on (it swerves),
    # the safety controller backs off and turns the nose away, clockwise
    cmd = nav.step(0.1, pose, 0.15, 0.0, _scan_with_point(0.38, 0.21))
    assert (cmd.status, cmd.v, cmd.w) == ("safety", p.dwa.escape_vel, -p.safety.safety_turn_vel)
    assert nav.state is NavState.SAFETY
    # the manoeuvre lasts safety_backoff_time, then the goal layer drives again
    t = 0.2
    while t < 0.1 + p.safety.safety_backoff_time - 1e-9:
        assert nav.step(t, pose, p.dwa.escape_vel, 0.0, NO_HITS).status == "safety"
        t += 0.1
    assert nav.step(t + 0.1, pose, 0.0, 0.0, NO_HITS).status == "driving"
    S = NavState
    assert nav.stats.transitions[(S.DRIVING, S.SAFETY)] == 1 == nav.safety.n_triggers
    assert nav.stats.transitions[(S.SAFETY, S.DRIVING)] == 1


def test_transitions_table_names_each_state_once_and_no_self_loops():
    assert set(TRANSITIONS) == set(NavState)
    for state, nexts in TRANSITIONS.items():
        assert state not in nexts and all(isinstance(s, NavState) for s in nexts)
        assert all(why for why in nexts.values())


def _unreachable_world() -> World:
    # a room behind a 0.45 m slit, which the robot glimpses: the narrow fallback plans
    # through it, the robot cannot pass it with its padding (its goals there fail, it backs
    # out), furniture-free otherwise. (A slit under the robot's width is no goal at all: no
    # plan crosses inscribed cells beyond the escape radius.)
    occ = _box(5.0, 9.0)
    occ[:, _cells(5.0) : _cells(5.1)] = True
    occ[_cells(2.4) : _cells(2.85), _cells(5.0) : _cells(5.1)] = False
    occ[_cells(3.5) : _cells(3.6), _cells(5.1) :] = True
    return World.from_array(occ, RES, start_pose=(1.5, 1.5, 0.0), name="unreachable")


def test_a_whole_run_changes_state_only_as_the_table_says():
    world = _unreachable_world()
    rng = np.random.default_rng(3)
    sim = Simulator(world, SimParams(), rng)
    slam = make_slam("odometry", SimParams().laser, SlamParams(), rng)
    run = Exploration(world, sim, slam, explore_params(time_limit=900.0), True, None)
    nav = run.nav
    S = NavState
    visited = set()
    stop = None
    while stop is None:
        stop = run.step()
        visited.add(nav.state)
        # each state's data is there, and only there
        assert (nav.state is S.RETRACING) == (nav.retrace is not None)
        if nav.state in (S.IDLE, S.EXHAUSTED):
            assert nav.pursuit is None
        if nav.state in (S.PLANNING, S.DRIVING, S.ESCAPING, S.RECOVERING):
            assert (nav.pursuit.path is None) == (nav.state is S.PLANNING)
        if nav.state is S.RECOVERING:
            assert nav.pursuit.ctrl_fail_since is not None
    assert stop.reason == "no_frontier"
    for (a, b), n in nav.stats.transitions.items():
        assert b in TRANSITIONS[a], (a, b, n)
    # the run went through its goals, gave some up and backed out (the safety stop, which
    # this run no longer meets since wall faces are no frontiers, has its own test below)
    assert {S.DRIVING, S.RETRACING, S.EXHAUSTED} <= visited
    assert nav.stats.transitions[(S.DRIVING, S.SAFETY)] == run.result(stop).safety_triggers


def test_the_door_passage_forward_motion_is_the_safety_controllers_to_veto():
    # door_align on, the robot on the axis of a 0.7 m door in a wall 0.1 m thick, the
    # unexplored room beyond it: the door passage drives; something the map lacks appears
    # 0.1 m in front of the footprint, on the axis: the safety controller backs off
    p = explore_params(door_align=True)
    nav = Navigator(p, ANGLES, 30.0)
    prob = np.full((80, 120), np.nan, dtype=np.float32)
    prob[:, :90] = 0.05  # known free to x = 4.5 m, unknown beyond
    prob[:, 60:62] = 0.9  # the wall, x in [3.0, 3.1)
    prob[33:47, 60:62] = 0.05  # the door, y in [1.65, 2.35)
    nav.update_map(prob, RES, (0.0, 0.0), True)
    pose = np.array([2.3, 2.0, 0.0])
    cmd = nav.step(0.0, pose, 0.0, 0.0, NO_HITS)
    assert nav.door.door is not None and cmd.status == "driving"
    assert (cmd.v, cmd.w) == (p.doors.door_speed, 0.0)
    cmd = nav.step(0.1, pose, cmd.v, 0.0, _scan_with_point(0.3, 0.0))
    assert (cmd.status, cmd.v) == ("safety", p.dwa.escape_vel) and nav.state is NavState.SAFETY
    assert nav.safety.n_triggers == 1


def _u_pursuit(nav: Navigator):
    """A goal 2 m east of the robot at (0, 0), reached by a plan round a wall between them:
    5 m north, 2 m east, 5 m south (12 m)."""
    from worker.explore.frontiers import FrontierGoal
    from worker.explore.nav_state import Pursuit

    legs = [np.column_stack((np.zeros(51), np.linspace(0, 5, 51)))]
    legs.append(np.column_stack((np.linspace(0, 2, 21)[1:], np.full(20, 5.0))))
    legs.append(np.column_stack((np.full(50, 2.0), np.linspace(5, 0, 51)[1:])))
    path = np.vstack(legs)
    goal = FrontierGoal(np.array([2.0, 0.0]), 0.0, np.array([2.3, 0.0]), 1.0, 1.0, 1, path)
    nav.pursuit = Pursuit(goal, 0.0, path, 1.0, progress_t=0.0)
    return path


def test_remaining_length_is_the_rest_of_the_plan_from_its_nearest_point():
    from worker.explore.planner import remaining_length

    nav = Navigator(ExploreParams(), ANGLES, 30.0)
    path = _u_pursuit(nav)
    # from (0.1, 3.0): 0.1 m to the plan's vertex (0, 3), then 2 + 2 + 5 m along it
    assert abs(remaining_length(path, (0.1, 3.0)) - 9.1) < 1e-9
    assert remaining_length(None, (0.0, 0.0)) == np.inf


def test_a_robot_driving_along_a_detour_makes_progress_and_one_standing_still_does_not():
    # explore_lite measures progress as the straight-line distance to the goal; along this
    # plan it grows for the first 5 m and is back to 2 m only after 10 m: at 0.15 m/s (the
    # door passage's speed) that is 67 s, over the 30 s progress_timeout
    p = ExploreParams()
    assert p.navigator.progress_timeout == 30.0
    nav = Navigator(p, ANGLES, 30.0)
    path = _u_pursuit(nav)
    d = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))))
    for k in range(0, 700):  # 70 s at 10 Hz, 0.15 m/s along the plan
        t = 0.1 * k
        s = 0.15 * t
        xy = np.array([np.interp(s, d, path[:, 0]), np.interp(s, d, path[:, 1])])
        assert not nav._no_progress(t, np.array([xy[0], xy[1], 0.0])), f"given up at {t} s"
    still = Navigator(p, ANGLES, 30.0)
    _u_pursuit(still)
    stops = [t for t in np.arange(0.0, 40.0, 0.1) if still._no_progress(t, np.zeros(3))]
    assert abs(stops[0] - 30.0) < 0.11  # no nearer in any sense: given up after 30 s


def _room_sealed_by_a_closed_gap(reopens: int) -> tuple[Navigator, np.ndarray]:
    # the robot's room (x, y 0.25-2.5 m) with a 1 m door in its top wall (x 1.0-2.0), a
    # corridor above it (y 2.75-4) open to the unknown 4 m to the right; the door's cells are
    # a gap closed after a failure (ClosedGaps), as if the robot had failed to leave by it
    nav = Navigator(explore_params(closed_gap_reopens=reopens), ANGLES, 30.0)
    prob = np.full((90, 200), 0.9, dtype=np.float32)
    prob[5:50, 5:50] = 0.05
    prob[50:55, 20:40] = 0.05  # the door
    prob[55:80, 5:150] = 0.05
    prob[55:80, 150:] = np.nan
    nav.update_map(prob, RES, (0.0, 0.0), True)
    xs = np.arange(1.0, 2.0, 0.05) + 0.025
    nav.closed.points = np.column_stack((xs, np.full(xs.size, 2.625)))
    return nav, np.array([1.5, 1.0, np.pi / 2])


def test_a_closed_gap_that_seals_the_robot_in_is_opened_when_nothing_else_is_left():
    nav, pose = _room_sealed_by_a_closed_gap(reopens=0)
    cmd = nav.step(0.0, pose, 0.0, 0.0, NO_HITS)
    assert cmd.status == "no_frontier"  # sealed: no frontier, no look through the door
    nav, pose = _room_sealed_by_a_closed_gap(reopens=1)
    cmd = nav.step(0.0, pose, 0.0, 0.0, NO_HITS)
    assert nav.state is NavState.DRIVING and cmd.status != "no_frontier"
    assert nav.goal.goal_xy[0] > 6.0 and not nav.goal.look_through  # the corridor's end
    assert len(nav.closed.points) == 0 and nav.chooser._reopens_left == 0


def _past_a_narrowed_gap(trap_reach: float) -> tuple[Navigator, np.ndarray]:
    # the robot at (2.6, 2) drove east along y = 2 (the DWA's forward commands) through a
    # wall at x 2.0-2.1 that the map now draws open only at y 1.85-2.15 (0.3 m, as seen from
    # this side); its goal lies east, with unknown space from x = 4 m
    from worker.explore.frontiers import FrontierGoal
    from worker.explore.nav_state import Pursuit

    nav = Navigator(explore_params(trail_spacing=0.04, trap_reach=trap_reach), ANGLES, 30.0)
    prob = np.full((80, 100), np.nan, dtype=np.float32)
    prob[:, :80] = 0.05
    ys = (np.arange(80) + 0.5) * RES
    prob[(ys < 1.85) | (ys > 2.15), 40:42] = 0.9
    nav.update_map(prob, RES, (0.0, 0.0), True)
    for i in range(53):
        nav.trail.grow(np.array([0.05 * i, 2.0, 0.0]), True)
    path = np.column_stack((np.linspace(2.6, 3.6, 21), np.full(21, 2.0)))
    goal = FrontierGoal(np.array([3.6, 2.0]), 0.0, np.array([3.975, 2.0]), 1.0, 1.0, 1, path)
    nav.pursuit = Pursuit(goal, 0.0, path, 1e9, progress_t=0.0)
    nav.dwa.set_plan(path)
    nav._next_choice_t = 1e9  # keep this goal: no new choice in the step below
    nav._enter(NavState.DRIVING)
    return nav, np.array([2.6, 2.0, 0.0])


def test_a_robot_past_a_gap_the_map_closed_behind_it_gives_up_and_backs_out_at_once():
    nav, pose = _past_a_narrowed_gap(trap_reach=1.0)
    cmd = nav.step(0.0, pose, 0.3, 0.0, NO_HITS)
    # the goal given up as trapped, the back-out under way to the trail point 1.2 m before
    # the first pose the map now walls in (x = 1.85): x = 0.65 (test_recovery, by hand)
    assert nav.stats.goals[-1].status == "failed" and nav.stats.goals[-1].detail == "trapped"
    assert nav.state is NavState.RETRACING and cmd.status == "recovering"
    assert abs(nav.retrace.target[0] - 0.65) < 1e-9 and nav.retrace.target[1] == 2.0
    # backing: the rear points at the target already, so the robot reverses straight
    cmd = nav.step(0.1, pose, 0.0, 0.0, NO_HITS)
    assert cmd.v < 0.0 and cmd.w == 0.0 and cmd.status == "recovering"
    # the trap check off: the robot drives on to its goal
    nav, pose = _past_a_narrowed_gap(trap_reach=0.0)
    cmd = nav.step(0.0, pose, 0.3, 0.0, NO_HITS)
    assert nav.pursuit is not None and not nav.stats.goals and cmd.v > 0.0
