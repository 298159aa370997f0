"""Trajectory and relations files: CARMEN layouts, TUM, round trips, errors naming the line."""

from __future__ import annotations

import gzip
import math

import numpy as np
import pytest

from worker.errors import InputError
from worker.evaluate.relations import Relations
from worker.evaluate.trajectory import Trajectory
from worker.evaluate.trajio import (
    read_relations,
    read_trajectory,
    write_carmen,
    write_relations,
    write_tum,
)


@pytest.fixture
def traj(rng):
    n = 50
    t = 100.0 + np.arange(n) * 0.1
    poses = np.column_stack(
        [rng.normal(0, 10, n), rng.normal(0, 10, n), rng.uniform(-math.pi, math.pi, n)]
    )
    return Trajectory(t, poses)


def assert_same(a: Trajectory, b: Trajectory, atol=1e-8):
    np.testing.assert_allclose(a.t, b.t, atol=1e-6)
    np.testing.assert_allclose(a.poses[:, :2], b.poses[:, :2], atol=atol)
    np.testing.assert_allclose(np.sin(a.poses[:, 2] - b.poses[:, 2]), 0.0, atol=atol)


def test_thesis_flaser_excerpt(tmp_path):
    # verbatim from the thesis (section 5.2.5): each pose written twice
    text = (
        "FLASER 0 0.0 0.0 0.0 -45.9153122597 15.4101963164 3.12809938018 4215.9\n"
        "FLASER 0 0.0 0.0 0.0 -45.9153122597 15.4101963164 3.12809938018 4215.9\n"
        "FLASER 0 0.0 0.0 0.0 -45.9254113403 15.4103325943 3.12809938018 4216.0\n"
        "FLASER 0 0.0 0.0 0.0 -45.9254113403 15.4103325943 3.12809938018 4216.0\n"
    )
    f = tmp_path / "est.log"
    f.write_text(text)
    tr = read_trajectory(f)
    np.testing.assert_array_equal(tr.t, [4215.9, 4216.0])
    np.testing.assert_array_equal(tr.poses[:, 0], [-45.9153122597, -45.9254113403])
    assert tr.poses[0, 2] == 3.12809938018


def test_real_carmen_log_layouts(tmp_path):
    # fields after the message: ipc_timestamp ipc_hostname logger_timestamp (CARMEN logger)
    lines = [
        "# CARMEN Logfile",
        "PARAM robot_length 0.4 nb 0.0",
        # FLASER 3 readings, laser pose (9, 9, 9), odom pose (1, 2, 0.5), ts 10.0
        "FLASER 3 1.0 2.0 3.0 9 9 9 1.0 2.0 0.5 10.0 nb 10.01",
        # ODOM x y theta tv rv accel
        "ODOM 7.0 8.0 0.1 0.3 0.0 0.0 10.05 nb 10.06",
        # TRUEPOS true pose then odom pose
        "TRUEPOS 4.0 5.0 -0.2 7.0 8.0 0.1 10.05 nb 10.06",
        # ROBOTLASER1 type start fov res maxr acc mode n=2 r r m=1 e laser(3) robot(3) tv rv
        # fwd side turn ts
        "ROBOTLASER1 0 -1.57 3.14 0.01 30 0.01 0 2 1.5 1.6 1 0.9 "
        "3 3 3 6.0 7.0 0.25 0 0 0 0 0 10.2 nb 10.21",
        "FLASER 3 1.0 2.0 3.0 9 9 9 1.5 2.5 0.6 10.1 nb 10.11",
    ]
    f = tmp_path / "real.log"
    f.write_text("\n".join(lines) + "\n")
    fl = read_trajectory(f)  # auto picks FLASER first
    np.testing.assert_array_equal(fl.t, [10.0, 10.1])
    np.testing.assert_array_equal(fl.poses, [[1.0, 2.0, 0.5], [1.5, 2.5, 0.6]])
    od = read_trajectory(f, message="ODOM")
    np.testing.assert_array_equal(od.poses, [[7.0, 8.0, 0.1]])
    tp = read_trajectory(f, message="TRUEPOS")
    np.testing.assert_array_equal(tp.poses, [[4.0, 5.0, -0.2]])
    assert tp.t[0] == 10.05
    rl = read_trajectory(f, message="ROBOTLASER1")
    np.testing.assert_array_equal(rl.poses, [[6.0, 7.0, 0.25]])
    assert rl.t[0] == 10.2


def test_flaser_lines_with_different_beam_counts_take_the_slow_path(tmp_path):
    f = tmp_path / "mixed.log"
    f.write_text(
        "FLASER 0 0 0 0 1 1 0.1 1.0\n"
        "FLASER 2 5 5 0 0 0 2 2 0.2 1.1 host 1.1\n"
        "FLASER 0 0 0 0 3 3 0.3 1.2\n"
    )
    tr = read_trajectory(f)
    np.testing.assert_array_equal(tr.poses[:, 0], [1.0, 2.0, 3.0])


def test_carmen_round_trip_and_gzip(tmp_path, traj):
    write_carmen(tmp_path / "a.log", traj)
    first = (tmp_path / "a.log").read_text().splitlines()[0].split()
    assert first[:5] == ["FLASER", "0", "0.0", "0.0", "0.0"] and len(first) == 9
    assert_same(read_trajectory(tmp_path / "a.log"), traj)
    write_carmen(tmp_path / "a.log.gz", traj)
    assert (tmp_path / "a.log.gz").read_bytes()[:2] == b"\x1f\x8b"
    assert_same(read_trajectory(tmp_path / "a.log.gz"), traj)
    # a gzip file is recognised by content, whatever its name
    (tmp_path / "plain_name.log").write_bytes(gzip.compress((tmp_path / "a.log").read_bytes()))
    assert_same(read_trajectory(tmp_path / "plain_name.log"), traj)


def test_tum_round_trip_and_yaw_from_quaternion(tmp_path, traj):
    write_tum(tmp_path / "a.tum", traj)
    assert_same(read_trajectory(tmp_path / "a.tum"), traj)
    # an unnormalised quaternion of yaw 0.7 about z, with an evo-style header line
    h = 0.35
    (tmp_path / "b.txt").write_text(
        f"# timestamp tx ty tz qx qy qz qw\n1.0 2 3 0 0 0 {2 * math.sin(h)} {2 * math.cos(h)}\n"
    )
    tr = read_trajectory(tmp_path / "b.txt")
    assert tr.poses[0, 2] == pytest.approx(0.7)


def test_tum_is_what_evo_reads(tmp_path, traj):
    from evo.tools import file_interface

    write_tum(tmp_path / "a.tum", traj)
    ev = file_interface.read_tum_trajectory_file(str(tmp_path / "a.tum"))
    np.testing.assert_allclose(ev.timestamps, traj.t, atol=1e-6)
    np.testing.assert_allclose(ev.positions_xyz[:, :2], traj.poses[:, :2], atol=1e-8)
    yaw = np.array([math.atan2(m[1, 0], m[0, 0]) for m in ev.poses_se3])
    np.testing.assert_allclose(np.sin(yaw - traj.poses[:, 2]), 0.0, atol=1e-8)


def test_relations_round_trip_with_comments(tmp_path, rng):
    rel = Relations(rng.uniform(0, 9, 20), rng.uniform(10, 20, 20), rng.normal(0, 3, (20, 3)))
    write_relations(tmp_path / "r.txt", rel)
    line = (tmp_path / "r.txt").read_text().splitlines()[0].split()
    assert len(line) == 8 and line[4:7] == ["0.0", "0.0", "0.0"]
    for name in ("r.txt", "r.txt.gz"):
        write_relations(tmp_path / name, rel)
        back = read_relations(tmp_path / name)
        np.testing.assert_allclose(back.t1, rel.t1, atol=1e-6)
        np.testing.assert_allclose(back.t2, rel.t2, atol=1e-6)
        np.testing.assert_allclose(back.delta, rel.delta, atol=1e-8)
    assert (tmp_path / "r.txt.gz").read_bytes()[:2] == b"\x1f\x8b"
    (tmp_path / "c.txt").write_text(
        "# Kuemmerle relations\n\n90.239599 90.719599 0.422330 -0.000750 0.000000 0.000000 "
        "0.000000 0.017260\n"
    )
    c = read_relations(tmp_path / "c.txt")
    np.testing.assert_array_equal(c.delta, [[0.422330, -0.000750, 0.017260]])


def test_empty_relations_file_is_zero_relations(tmp_path):
    (tmp_path / "e.txt").write_text("# nothing\n")
    assert len(read_relations(tmp_path / "e.txt")) == 0


@pytest.mark.parametrize(
    "body, line, words",
    [
        ("1 2 0.1 0.2 0 0 0 0.3\n1 2 0.1 0.2 0 0 0\n", 2, "expected 8 numbers"),
        ("# c\n\n1 2 0.1 0.2 0 0 0 0.3\n1 2 0.1 abc 0 0 0 0.3\n", 4, "not a number: 'abc'"),
        ("1 2 0.1 0.2 0 0 0 0.3\n1 2 nan 0.2 0 0 0 0.3\n", 2, "non-finite"),
        ("1 2 0.1 0.2 0 0 0\n1 2 0.1 0.2 0 0 0\n", 1, "expected 8 numbers"),
    ],
)
def test_malformed_relations_line_is_named(tmp_path, body, line, words):
    f = tmp_path / "bad.txt"
    f.write_text(body)
    with pytest.raises(InputError, match=words) as exc:
        read_relations(f)
    assert exc.value.line == line and exc.value.path == str(f)
    assert str(exc.value).startswith(f"{f}:{line}: ")


def test_malformed_carmen_line_is_named(tmp_path):
    f = tmp_path / "bad.log"
    f.write_text("FLASER 0 0 0 0 1 1 0.1 1.0\nODOM 1 2 3 0 0 0 1.0\nFLASER 0 0 0 0 1 x 0.1 1.1\n")
    with pytest.raises(InputError, match="malformed FLASER line") as exc:
        read_trajectory(f)
    assert exc.value.line == 3
    f.write_text("FLASER 5 0 0 0 1 1 0.1 1.0\n")  # says 5 readings, has too few fields
    with pytest.raises(InputError, match=":1: malformed FLASER"):
        read_trajectory(f)


def test_malformed_tum_and_missing_inputs(tmp_path):
    f = tmp_path / "bad.tum"
    f.write_text("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0\n")
    with pytest.raises(InputError, match=":2: expected 8 numbers"):
        read_trajectory(f)
    f.write_text("1 0 0 0 0 0 0 0\n")
    with pytest.raises(InputError, match="zero quaternion"):
        read_trajectory(f)
    with pytest.raises(InputError, match="no such file"):
        read_trajectory(tmp_path / "missing.log")
    g = tmp_path / "other.log"
    g.write_text("PARAM a 1\nSYNC x\n")
    with pytest.raises(InputError, match="no pose messages"):
        read_trajectory(g)
    with pytest.raises(InputError, match="no ODOM messages"):
        read_trajectory(g, fmt="carmen", message="ODOM")
    (tmp_path / "bin").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(InputError, match="not a text file|not a number|expected 8"):
        read_relations(tmp_path / "bin")
