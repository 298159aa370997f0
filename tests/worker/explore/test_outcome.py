"""A run's outcome: completed only when no reachable room was left unseen, else incomplete."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

from worker.evaluate.coverage import reachable_free, seen_free, unseen_regions
from worker.explore.loop import judge_outcome
from worker.explore.params import ExploreParams
from worker.explore.stop_rules import StopReason
from worker.report import summary
from worker.status import RunOutcome

RES = 0.1  # [m] the school plans' resolution


def _two_rooms(door_cells: int) -> np.ndarray:
    """(60, 120) bool world, True obstacle: rooms of 5.8 x 5.8 m joined by a door in x=60."""
    occ = np.zeros((60, 120), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    occ[:, 60] = True
    occ[30 : 30 + door_cells, 60] = False
    return occ


def test_a_room_behind_a_0_7_m_door_is_reachable_one_behind_0_3_m_is_not():
    # the 0.4 m robot (half side 0.2 m) fits through 0.7 m (7 cells at 0.1 m), not 0.3 m
    wide = reachable_free(_two_rooms(7), RES, (20, 20), 0.2)
    narrow = reachable_free(_two_rooms(3), RES, (20, 20), 0.2)
    assert wide[:, 61:].any() and not narrow[:, 62:].any()


def test_the_unseen_room_is_one_region_the_slivers_along_the_walls_are_none():
    occ = _two_rooms(7)
    reach = reachable_free(occ, RES, (20, 20), 0.2)
    seen = reach.copy()
    seen[:, 61:] = False  # the right room never seen
    seen[1:3, 1:60] = False  # a 0.2 m strip along the left room's bottom wall: no region
    regions = unseen_regions(reach, seen, RES, np.zeros(2), 2.0, 0.8)
    assert len(regions) == 1
    room = regions[0]
    # the right room: cells x 61..118, y 1..58 (58 x 58 = 33.64 m^2), all reachable; the
    # opening by a 0.8 m disc keeps it but rounds its four corners (r^2 (4 - pi) = 14 cells
    # at r = 4 cells, a little more on the grid)
    assert room.area_m2 == pytest.approx(58 * 58 * RES**2, rel=0.015)
    assert room.centre == pytest.approx((9.0, 3.0), abs=0.05)


def _stop(reason: str) -> StopReason:
    return StopReason(reason, "no reachable frontier left")


def test_a_done_run_that_left_a_room_unseen_is_incomplete_with_the_reason():
    occ = _two_rooms(7)
    reach = reachable_free(occ, RES, (20, 20), 0.2)
    world = SimpleNamespace(resolution=RES, origin=np.zeros(2))
    seen = reach.copy()
    seen[:, 61:] = False
    cov = np.count_nonzero(seen) / np.count_nonzero(reach)
    outcome, detail = judge_outcome(_stop("no_frontier"), reach, seen, world, cov, ExploreParams())
    assert outcome == RunOutcome.INCOMPLETE
    # the right room's 58 x 58 cells unseen; the coverage is not repeated in the line (the
    # run has it as a field, and the CLI printed it twice)
    # (the opening by the min_width disc rounds the room's four corners off: a little less)
    area = float(re.search(r"but ([0-9.]+) m\^2 of reachable space never seen", detail)[1])
    assert 0.97 * 58 * 58 * RES * RES <= area <= 58 * 58 * RES * RES
    assert "coverage" not in detail
    assert "1 region(s)" in detail and "at (9.0, 3.0)" in detail
    # everything seen: completed, the line unchanged
    outcome, detail = judge_outcome(_stop("no_frontier"), reach, reach, world, 1.0, ExploreParams())
    assert outcome == RunOutcome.COMPLETED and detail == "no reachable frontier left"
    # a failure stays a failure, however much was left
    collided = StopReason("collision", "hit")
    assert judge_outcome(collided, reach, seen, world, cov, ExploreParams())[0] == "failed"


def test_seen_free_maps_the_slam_grid_through_the_alignment():
    reach = np.ones((10, 10), dtype=bool)
    prob = np.full((10, 10), np.nan)
    prob[:, :5] = 0.0  # the map's left half free, in a frame shifted 0.5 m right
    seen = seen_free(reach, RES, np.zeros(2), prob, RES, np.zeros(2), 0.25, np.array([0.5, 0, 0]))
    assert seen[:, 5:].all() and not seen[:, :5].any()


def test_the_outcome_vocabulary_reaches_the_summary_and_the_tables():
    assert RunOutcome("incomplete") == RunOutcome.INCOMPLETE
    assert summary.RunSummary.model_fields["outcome"].annotation is RunOutcome


def test_success_table_counts_incomplete_runs_apart_from_completed_and_failed():
    from worker.batch.tables import success_rows

    def rec(outcome, reason):
        s = SimpleNamespace(outcome=outcome, reason=reason, relation=lambda kind: None)
        return {"world": "Borchen4", "variant": "", "noise": 0.0, "slam": "odometry",
                "status": "done", "summary": s}  # fmt: skip

    raised = {"world": "Borchen4", "variant": "", "noise": 0.0, "slam": "odometry",
              "status": "error", "summary": None}  # fmt: skip
    records = [
        rec("completed", None), rec("incomplete", "no_frontier"),
        rec("incomplete", "map_unchanged"), rec("failed", "stuck"), raised,
    ]  # fmt: skip
    (row,) = success_rows(records)
    assert (row["runs"], row["completed"], row["incomplete"], row["failed"]) == (5, 1, 2, 2)
    assert (row["stuck"], row["error"], row["collision"]) == (1, 1, 0)


def test_rooms_behind_doors_narrower_than_the_robot_drives_through_do_not_make_it_incomplete():
    # Histor4's rooms off the inner corridor have 0.5 m doors. The centre of the 0.4 m robot
    # must keep 0.2 m (half side) + 0.02 m (padding) + 0.05 m (a SLAM cell lost each side)
    # = 0.27 m: at 0.1 m per cell a cell 4 cells from both jambs has (4 - 0.5) 0.1 = 0.35 m,
    # one 3 cells away 0.25 m; a door of n cells has a cell 4 away from both when n >= 7.
    p = ExploreParams()
    assert p.passable_clearance_m == pytest.approx(0.27)
    world = SimpleNamespace(resolution=RES, origin=np.zeros(2))
    for door, expected in ((5, RunOutcome.COMPLETED), (6, RunOutcome.COMPLETED), (7, "incomplete")):
        occ = _two_rooms(door)
        reach = reachable_free(occ, RES, (20, 20), 0.2)
        assert reach[:, 62:].any()  # the bare half side passes all three doors
        passable = reachable_free(occ, RES, (20, 20), 0.2, p.passable_clearance_m)
        assert passable[:, 62:].any() == (door >= 7)
        seen = reach.copy()
        seen[:, 61:] = False  # the right room never seen
        outcome, _ = judge_outcome(_stop("no_frontier"), passable, seen, world, 0.5, p)
        assert outcome == expected
