"""ExploreParams validation and its groups: the navigation constants are checked like every
other field, and the flat keys of before the groups still name them."""

from __future__ import annotations

import dataclasses

import pytest

from worker.errors import InputError
from worker.explore.flat_params import FLAT_KEYS, GROUPS, explore_params, nest_flat
from worker.explore.params import ExploreParams
from worker.param_io import from_dict


@pytest.mark.parametrize(
    "name", ["same_goal_distance", "recovery_delay", "trail_spacing", "stuck_distance"]
)
def test_a_negative_or_zero_setting_is_named_in_the_error(name):
    for bad in (-1.0, 0.0):
        with pytest.raises(InputError, match=f"must be positive: {name}"):
            from_dict(ExploreParams, nest_flat({name: bad}), "explore")


def test_margins_may_be_zero():
    p = explore_params(look_fov_margin=0.0, goal_search_extra=0.0)
    assert p.frontiers.look_fov_margin == 0.0 and p.frontiers.goal_search_extra == 0.0


def test_the_trail_cannot_drop_more_points_than_it_keeps():
    with pytest.raises(InputError, match="trail_trim exceeds trail_cap"):
        explore_params(trail_cap=10, trail_trim=11)
    assert explore_params(trail_cap=10, trail_trim=10).recovery.trail_trim == 10


def test_every_field_is_in_one_group_or_the_loops_own():
    groups = {g: getattr(ExploreParams(), g) for g in GROUPS}
    names = [f.name for g in GROUPS for f in dataclasses.fields(groups[g])]
    assert len(names) == len(set(names)) == len(FLAT_KEYS)  # no name in two groups
    own = [f.name for f in dataclasses.fields(ExploreParams) if f.name not in GROUPS]
    assert "time_limit" in own and not set(own) & set(names)
    # 120 settings before the groups, 120 after; 121 with issue 52's snapshot_holds_area
    assert len(names) + len(own) == 121


def test_flat_keys_go_to_their_groups_and_nested_ones_stay():
    flat = {"door_align": True, "time_limit": 60.0, "trail_cap": 150, "dwa": {"max_vel_x": 0.5}}
    nested = nest_flat(flat)
    assert nested == {
        "time_limit": 60.0,
        "dwa": {"max_vel_x": 0.5},
        "doors": {"door_align": True},
        "recovery": {"trail_cap": 150},
    }
    assert flat["dwa"] == {"max_vel_x": 0.5}  # the caller's mapping is left alone
    p = from_dict(ExploreParams, nested, "explore")
    assert p.doors.door_align and p.recovery.trail_cap == 150 and p.dwa.max_vel_x == 0.5
    assert nest_flat({"doors": {"door_align": True}}) == {"doors": {"door_align": True}}


def test_a_key_given_flat_and_nested_is_refused():
    with pytest.raises(InputError, match="door_align is given twice"):
        nest_flat({"door_align": True, "doors": {"door_align": False}})


def test_an_unknown_flat_key_is_refused_with_the_valid_ones():
    with pytest.raises(InputError, match=r"unknown parameter explore\.door_allign \(valid: "):
        explore_params(door_allign=True)
    with pytest.raises(InputError, match=r"unknown parameter explore\.doors\.door_allign"):
        explore_params(doors={"door_allign": True})
