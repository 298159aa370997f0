"""The map score of whole runs: the oracle's map is the floorplan, a drifting one is worse."""

from __future__ import annotations

import json

import numpy as np
from PIL import Image

from tests.worker.test_pipeline import two_rooms
from worker.pipeline import run_one
from worker.report.folder import SUMMARY, write_report
from worker.report.plots import BOTH_RGB, FLOORPLAN_WALL_RGB, MAP_WALL_RGB
from worker.run_params import RunParams


def test_the_oracles_map_matches_the_floorplan_and_lands_in_summary_and_overlay(tmp_path):
    p = RunParams.from_json({"algorithm": "oracle", "explore": {"time_limit": 120.0}})
    r = run_one(two_rooms(), p, seed=3)
    m = r.summary.map_score
    # ground-truth poses, noise-free laser: every wall a beam hits lies on a floorplan wall
    # cell, so within a cell (0.05 m) at worst, and the registration stays at the start pose
    assert m.precision >= 0.99 and m.recall >= 0.95
    assert m.distance_m < 0.05
    assert m.walls == "density" and m.walls_sigma_m == 0.05  # noise-free: one cell
    a = m.alignment
    assert abs(a.x) < 0.02 and abs(a.y) < 0.02 and abs(a.theta) < 0.005
    assert m.free_share == r.summary.coverage or abs(m.free_share - r.summary.coverage) < 0.02
    write_report(r, tmp_path)
    assert json.loads((tmp_path / SUMMARY).read_text())["map_score"]["precision"] == m.precision
    img = np.asarray(Image.open(tmp_path / "map_overlay.png").convert("RGB"))
    colours = {tuple(c) for c in img.reshape(-1, 3)[::7]}
    assert {FLOORPLAN_WALL_RGB, BOTH_RGB} <= colours or {MAP_WALL_RGB, BOTH_RGB} <= colours


def test_a_drifting_odometry_scores_worse_than_the_oracle():
    common = {"explore": {"time_limit": 120.0}, "sim": {"odom_error": [0.1, 0.1, 0.2]}}
    oracle = run_one(two_rooms(), RunParams.from_json({"algorithm": "oracle", **common}), 5)
    odo = run_one(two_rooms(), RunParams.from_json({"algorithm": "odometry", **common}), 5)
    a, b = oracle.summary.map_score, odo.summary.map_score
    assert b.distance_m > a.distance_m and b.precision < a.precision


def test_a_noisy_lasers_map_is_scored_with_the_end_points_smoothed_by_its_noise():
    p = {"algorithm": "rbpf", "slam": {"particles": 5}, "explore": {"time_limit": 60.0},
         "sim": {"laser_noise_sigma": 0.1}}  # fmt: skip
    m = run_one(two_rooms(), RunParams.from_json(p), 2).summary.map_score
    assert (m.walls, m.walls_sigma_m) == ("density", 0.1)
