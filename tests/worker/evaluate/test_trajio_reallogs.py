"""Trajectory and relations files as real tools leave them: steps back in time, duplicate
lines, a truncated last line (issue 17 section 1)."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from worker.errors import InputError, InputWarning
from worker.evaluate.trajio import read_relations, read_trajectory


def tum(t, x):
    return f"{t} {x} 0 0 0 0 0 1\n"


def test_tum_out_of_order_and_duplicates_are_repaired_with_warnings(tmp_path):
    path = tmp_path / "est.tum"
    path.write_text(
        "# t x y z qx qy qz qw\n" + tum(1.0, 0) + tum(1.2, 2) + tum(1.1, 1) + tum(1.1, 1)
    )
    with pytest.warns(InputWarning) as caught:
        traj = read_trajectory(path)
    messages = " | ".join(str(w.message) for w in caught)
    assert "1 exact duplicate poses dropped" in messages
    assert "1 poses out of time order: sorted (stable)" in messages
    assert traj.t.tolist() == [1.0, 1.1, 1.2] and traj.poses[:, 0].tolist() == [0, 1, 2]


def test_a_truncated_last_tum_line_is_skipped(tmp_path):
    path = tmp_path / "est.tum"
    path.write_text(tum(1.0, 0) + tum(2.0, 1) + "3.0 2 0 0 0")
    with pytest.warns(InputWarning, match=r"est.tum:3: the last line is truncated: skipped"):
        traj = read_trajectory(path)
    assert traj.t.tolist() == [1.0, 2.0]


def test_a_bad_tum_line_with_its_newline_is_still_an_error(tmp_path):
    path = tmp_path / "est.tum"
    path.write_text(tum(1.0, 0) + "2.0 1 0 0 0\n" + tum(3.0, 2))
    with pytest.raises(InputError, match=r"est.tum:2: expected 8 numbers"):
        read_trajectory(path)


def test_a_truncated_carmen_log_and_relations_file(tmp_path):
    log = tmp_path / "gt.log.gz"
    text = "".join(f"ODOM {k} 0 0 0 0 0 {k}.5 h {k}.5\n" for k in range(300))
    data = gzip.compress(text.encode())
    log.write_bytes(data[: len(data) // 2])
    with pytest.warns(InputWarning, match="gzip data ends early"):
        traj = read_trajectory(log)
    assert 10 < len(traj) < 300
    np.testing.assert_allclose(traj.t, np.arange(len(traj)) + 0.5)
    rel = tmp_path / "rel.txt"
    rel.write_text("1 2 0.5 0 0 0 0 0.1\n2 3 0.5 0 0 0 0 0.2\n3 4 0.5")
    with pytest.warns(InputWarning, match=r"rel.txt:3: the last line is truncated"):
        relations = read_relations(rel)
    assert relations.t1.tolist() == [1.0, 2.0]
