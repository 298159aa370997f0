"""ExploreParams validation: the navigation constants are checked like every other field."""

from __future__ import annotations

import pytest

from worker.errors import InputError
from worker.explore.params import ExploreParams
from worker.param_io import from_dict


@pytest.mark.parametrize(
    "name", ["same_goal_distance", "recovery_delay", "trail_spacing", "stuck_distance"]
)
def test_a_negative_or_zero_setting_is_named_in_the_error(name):
    for bad in (-1.0, 0.0):
        with pytest.raises(InputError, match=name):
            from_dict(ExploreParams, {name: bad}, "explore")


def test_margins_may_be_zero():
    p = from_dict(ExploreParams, {"look_fov_margin": 0.0, "goal_search_extra": 0.0})
    assert p.look_fov_margin == 0.0 and p.goal_search_extra == 0.0


def test_the_trail_cannot_drop_more_points_than_it_keeps():
    with pytest.raises(InputError, match="trail_trim exceeds trail_cap"):
        ExploreParams(trail_cap=10, trail_trim=11)
    assert ExploreParams(trail_cap=10, trail_trim=10).trail_trim == 10
