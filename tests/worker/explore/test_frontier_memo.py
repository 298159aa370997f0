"""Issue 52: the frontier choice and the global plan answered from memory equal the ones made
from scratch, after random map edits (each read through its own window), looks and questions."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.worker.explore.test_incremental import FREE, OCC, ORIGIN, RES, H, W, _apply
from worker.explore.costmap import GlobalCostmap
from worker.explore.flat_params import explore_params
from worker.explore.frontiers import FrontierGoal, FrontierSearch
from worker.explore.params import ExploreParams
from worker.explore.planner import DijkstraSearch, GlobalPlanner

# the incremental costmap test's map and edit writer (the same 2.8 m x 3.2 m grid)
# robot positions [m] in the starting room (a few, so that questions repeat)
SPOTS = [(ORIGIN[0] + (30 + 0.5) * RES, ORIGIN[1] + (26 + 0.5) * RES), (2.62, -0.61), (2.9, -0.3)]

edit = st.tuples(
    st.just("edit"),
    st.integers(0, H - 1),
    st.integers(0, W - 1),
    st.integers(1, 12),
    st.integers(1, 12),
    st.sampled_from([np.nan, FREE, OCC]),
)
# (spot, what becomes of the answer's frontier: nothing, blacklisted or spent, look_through,
# squeeze)
ask = st.tuples(
    st.just("ask"),
    st.integers(0, len(SPOTS) - 1),
    st.sampled_from(["", "blacklist", "spent"]),
    st.booleans(),
    st.booleans(),
)
look = st.tuples(st.just("look"), st.integers(0, len(SPOTS) - 1), st.floats(-math.pi, math.pi))
SETTINGS = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _params() -> ExploreParams:
    # small goal radius and frontier size: the 2.8 m x 3.2 m test map has room for goals
    return explore_params(min_frontier_size=0.15, dead_frontier_looks=2)


def _window(prob: np.ndarray, op) -> tuple[float, float, float, float]:
    """Write the edit `("edit", y0, x0, h, w, value)` into prob; the window [m] that holds it."""
    return _apply(prob, op[1:])


def _from_scratch(prob: np.ndarray, seen: np.ndarray, question) -> FrontierGoal | None:
    """The choice of a new costmap and frontier search built from the whole map now, with the
    same look counts."""
    p = _params()
    cm, fs = GlobalCostmap(p.costmap), FrontierSearch(p.frontiers, p.planner)
    fs.update(cm, cm.update(prob, RES, ORIGIN))
    fs.seen[:] = seen
    xy, blacklist, look_through, squeeze, spent = question
    return fs.find_goal(
        cm, xy, blacklist, [], look_through=look_through, squeeze=squeeze, spent=spent
    )


def _same(a: FrontierGoal | None, b: FrontierGoal | None) -> bool:
    if a is None or b is None:
        return a is b
    arrays = ("goal_xy", "frontier_xy", "path_xy")
    scalars = ("yaw", "cluster_size_m", "travel_cost", "n_clusters", "look_through", "squeeze")
    return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in arrays) and all(
        getattr(a, k) == getattr(b, k) for k in scalars
    )


def _run(ops) -> FrontierSearch:
    p = _params()
    prob = np.full((H, W), np.nan, dtype=np.float32)
    prob[20:36, 24:40] = FREE  # a known room, open to the unknown on all sides
    prob[20:36, 23] = OCC
    cm, fs = GlobalCostmap(p.costmap), FrontierSearch(p.frontiers, p.planner)
    fs.update(cm, cm.update(prob, RES, ORIGIN))
    given_up: dict[str, list[np.ndarray]] = {"blacklist": [], "spent": []}
    for op in ops:
        if op[0] == "edit":
            fs.update(cm, cm.update(prob, RES, ORIGIN, window_m=_window(prob, op)))
        elif op[0] == "look":
            x, y = SPOTS[op[1]]
            fs.observe(cm, np.array([x, y, op[2]]), math.radians(120.0))
        else:
            _, spot, drop, look_through, squeeze = op
            blacklist, spent = list(given_up["blacklist"]), list(given_up["spent"])
            question = (SPOTS[spot], blacklist, look_through, squeeze, spent)
            got = fs.choose(cm, SPOTS[spot], blacklist, [], look_through, squeeze, spent)
            assert _same(got, _from_scratch(prob, fs.seen, question))
            if drop and got is not None:
                given_up[drop].append(got.frontier_xy)
    return fs


@SETTINGS
@given(st.lists(st.one_of(edit, ask, ask, look), min_size=1, max_size=16))
def test_remembered_choices_equal_choices_from_scratch(ops):
    _run(ops)


def test_the_same_question_on_the_same_map_is_answered_from_memory():
    # an independent count: questions repeated with nothing changed in between are hits,
    # and a map edit or a look that counts makes the next question a miss
    ask0 = ("ask", 0, False, False, False)
    fs = _run([ask0, ask0, ask0])
    assert fs.memo.hits == 2
    fs = _run([ask0, ("edit", 20, 40, 16, 2, FREE), ask0, ask0])
    assert fs.memo.hits == 1
    fs = _run([ask0, ("edit", 0, 0, 2, 2, np.nan), ask0])  # nothing changed: unknown already
    assert fs.memo.hits == 1
    # the answer's frontier blacklisted or spent: a new question (each checked from scratch)
    for drop in ("blacklist", "spent"):
        assert _run([("ask", 0, drop, False, False), ask0]).memo.hits == 0
    # the room's right side in view: a look is counted, a second makes its cells dead
    # (dead_frontier_looks = 2), which changes the choice
    fs = _run([ask0, ("look", 0, 0.0), ask0])
    assert fs.memo.hits == 1 and fs.seen.max() == 1
    fs = _run([ask0, ("look", 0, 0.0), ("look", 0, 0.0), ask0])
    assert fs.memo.hits == 0 and fs.seen.max() == 2


# (start spot, goal spot, squeeze)
plan = st.tuples(
    st.just("plan"),
    st.integers(0, len(SPOTS) - 1),
    st.integers(0, len(SPOTS) - 1),
    st.booleans(),
)


def _plans(ops) -> tuple[GlobalPlanner, GlobalCostmap]:
    """A planner told of every costmap change (as the navigator tells it), asked the `plan`
    ops between the edits; each answer checked against a new planner on a new costmap."""
    p = _params()
    prob = np.full((H, W), np.nan, dtype=np.float32)
    prob[20:36, 24:40] = FREE
    cm, planner = GlobalCostmap(p.costmap), GlobalPlanner(p.planner)
    cm.update(prob, RES, ORIGIN)
    planner.map_changed()
    for op in ops:
        if op[0] == "edit":
            changed = cm.update(prob, RES, ORIGIN, window_m=_window(prob, op))
            if changed[1] > changed[0]:
                planner.map_changed()
            continue
        _check_plan(planner, cm, prob, op)
    return planner, cm


def _check_plan(planner: GlobalPlanner, cm: GlobalCostmap, prob: np.ndarray, op) -> None:
    """The plan of `op` ("plan", start spot, goal spot, squeeze) equals a new planner's on a
    costmap built anew from `prob`."""
    p = _params()
    _, a, b, squeeze = op
    got = planner.plan(cm, SPOTS[a], SPOTS[b], squeeze)
    fresh = GlobalCostmap(p.costmap)
    fresh.update(prob, RES, ORIGIN)
    want = GlobalPlanner(p.planner).plan(fresh, SPOTS[a], SPOTS[b], squeeze)
    assert (got is None and want is None) or np.array_equal(got, want)


@SETTINGS
@given(st.lists(st.one_of(edit, plan, plan), min_size=1, max_size=16))
def test_kept_plans_equal_plans_from_scratch(ops):
    _plans(ops)


def test_a_plan_asked_again_on_the_same_map_is_not_searched_again():
    planner, cm = _plans([("plan", 0, 2, False)])
    searches = planner.search.run_id  # one a search (and one a sealed-pocket test)
    first = planner.plan(cm, SPOTS[0], SPOTS[2])
    assert first is not None and planner.search.run_id == searches
    planner.map_changed()
    assert np.array_equal(planner.plan(cm, SPOTS[0], SPOTS[2]), first)
    assert planner.search.run_id > searches


def _shared(ops) -> None:
    """The frontier search and the planner on one set of Dijkstra buffers, as the navigator
    builds them (the clusters' labelling, the unknown flood, the goal search and the plans
    all mark the same stamp grid, each pass with its own id): every choice and plan equals
    the one of a search or planner with buffers of its own, on a costmap built anew."""
    p = _params()
    prob = np.full((H, W), np.nan, dtype=np.float32)
    prob[20:36, 24:40] = FREE
    prob[20:36, 23] = OCC
    search = DijkstraSearch()
    cm = GlobalCostmap(p.costmap)
    fs = FrontierSearch(p.frontiers, p.planner, search=search)
    planner = GlobalPlanner(p.planner, search=search)
    fs.update(cm, cm.update(prob, RES, ORIGIN))
    for op in ops:
        if op[0] == "edit":
            fs.update(cm, cm.update(prob, RES, ORIGIN, window_m=_window(prob, op)))
        elif op[0] == "plan":
            _check_plan(planner, cm, prob, op)
        else:
            _, spot, _, look_through, squeeze = op
            got = fs.find_goal(cm, SPOTS[spot], [], [], look_through, squeeze)
            assert _same(
                got, _from_scratch(prob, fs.seen, (SPOTS[spot], [], look_through, squeeze, []))
            )


@SETTINGS
@given(st.lists(st.one_of(edit, ask, plan), min_size=1, max_size=16))
def test_searches_sharing_one_stamp_grid_answer_as_with_their_own(ops):
    _shared(ops)
