"""The tutorials' commands, as the pages write them (short simulated times), so the manual
cannot rot: a renamed option, a moved file or a changed output fails here."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.docs.tutorial_commands import ROOT, SHORT_S, page_commands, run, workspace

pytestmark = pytest.mark.slow


def _run_page(page: str, workdir: Path) -> dict[str, str]:
    """Run every command of `page` in order; each command's stdout by its line."""
    commands = page_commands(page)
    assert commands, f"{page} has no command to run"
    return {c.line: run(c, workdir).stdout for c in commands}


def test_a_first_run(tmp_path):
    work = workspace(tmp_path)
    # the page's own floorplan image: a plain picture of a building, as a user has one
    shutil.copy(ROOT / "worlds/bormann/no_furniture/office_a.png", work / "my_floor.png")
    out = _run_page("tutorials/first-run.md", work)
    report = work / "out/first"
    summary = json.loads((report / "summary.json").read_text())
    # a run cut at the short limit ends as the page says a cut run ends
    assert summary["outcome"] == "failed" and summary["reason"] == "time_limit"
    assert summary["timings"]["sim_time_s"] == pytest.approx(SHORT_S, abs=0.2)
    # every file the page's table names is there
    page = (ROOT / "docs/tutorials/first-run.md").read_text()
    table = page.split("## What the run writes", 1)[1].split("\n## ", 1)[0]
    named = re.findall(r"`([\w.]+\.(?:json|pgm|yaml|png|txt|errors|tum|log|zip))`", table)
    assert len(named) >= 15, named
    # report.zip is made in runs/<id>/ only, as the page says
    missing = [n for n in named if n != "report.zip" and not (report / n).is_file()]
    assert not missing, f"the page names files the run did not write: {missing}"
    # `runs show 1 --json` is the first run, as stored
    shown = json.loads(out["mapqual runs show 1 --json"])
    assert json.dumps(shown).count("office_a") >= 1
    # the stages on their own made a B score from the simulated log
    evaluated = json.loads(
        out["mapqual evaluate --relations relations_B.txt --est slam/trajectory.tum --json"]
    )
    assert json.dumps(evaluated).count("translation") >= 1
    assert json.loads((work / "summary.json").read_text())["world"]


def test_comparing_algorithms(tmp_path):
    work = workspace(tmp_path)
    out = _run_page("tutorials/compare-algorithms.md", work)
    import csv

    rows = list(csv.DictReader((work / "cmp/runs.csv").open()))
    slams = {r["slam"] for r in rows}
    assert slams == {"rbpf", "graph", "external:dead_reckoning"}, slams
    assert {r["seed"] for r in rows} == {"1", "2"}
    assert (work / "compare.png").stat().st_size > 5000
    assert (work / "compare_rot.png").stat().st_size > 5000
    # the plotted mean and half-width of one algorithm, derived here by hand from runs.csv
    printed = out["python examples/plot_compare.py cmp/runs.csv -o compare.png"]
    values = [float(r["b_mean_t"]) for r in rows if r["slam"] == "graph"]
    mean = float(np.mean(values))
    half = 12.706204736 * float(np.std(values, ddof=1)) / np.sqrt(2)  # t(0.975, 1 dof)
    line = next(ln for ln in printed.splitlines() if " graph " in ln)
    assert f"{mean:.4f} +- {half:.4f}" in line, (line, mean, half)


def test_scoring_your_slam_from_a_bag(tmp_path):
    work = workspace(tmp_path)
    commands = page_commands("tutorials/score-your-slam.md")
    *before, score = commands
    assert score.line.startswith("mapqual score")
    for c in before:
        run(c, work)
    folder = work / "runs/office_a_1"
    assert (work / "office_a_1/metadata.yaml").is_file()
    assert (work / "office_a_1.bag").stat().st_size > 10_000
    # what `ros2 bag record /tf /tf_static` of a SLAM node gives: map -> base_link in /tf;
    # here the node's estimate is the run's own online estimate, so its score is known
    _record_tf_bag(folder / "est.tum", work / "recorded")
    printed = run(score, work).stdout
    assert "slam_toolbox" in printed
    mine = json.loads((folder / "estimates/slam_toolbox/summary.json").read_text())
    own = json.loads((folder / "summary.json").read_text())
    for kind in ("B", "A", "SM"):  # SM is empty (null) on so short a run: then on both
        ours = own["relations"][kind]["translation"]["mean"]
        theirs = mine["relations"][kind]["translation"]["mean"]
        if ours is None:
            assert theirs is None, kind
        else:
            assert theirs == pytest.approx(ours, rel=1e-6, abs=1e-9), kind
    assert own["relations"]["B"]["translation"]["mean"] is not None


def _record_tf_bag(tum: Path, out: Path) -> None:
    """A rosbag2 with /tf map -> base_link at each pose of a TUM file, written with rosbags
    (as a node's recording would be), not with mapqual."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    msgs = store.types
    tf_type = "tf2_msgs/msg/TFMessage"
    data = np.loadtxt(tum)
    with Writer(out, version=8) as writer:
        conn = writer.add_connection("/tf", tf_type, typestore=store)
        for t, x, y, z, qx, qy, qz, qw in data:
            sec, nsec = divmod(int(round(t * 1e9)), 1_000_000_000)
            stamp = msgs["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
            header = msgs["std_msgs/msg/Header"](stamp=stamp, frame_id="map")
            transform = msgs["geometry_msgs/msg/Transform"](
                translation=msgs["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                rotation=msgs["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
            )
            tfs = msgs["geometry_msgs/msg/TransformStamped"](
                header=header, child_frame_id="base_link", transform=transform
            )
            message = msgs[tf_type](transforms=[tfs])
            writer.write(conn, sec * 1_000_000_000 + nsec, store.serialize_cdr(message, tf_type))
