"""`mapqual export`: a run's (or any CARMEN log's) sensor data as a ROS 2 or ROS 1 bag."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from mapqual.cli import app


class BagFmt(StrEnum):
    rosbag2 = "rosbag2"
    rosbag1 = "rosbag1"


@app.command("export")
def export_cmd(
    source: Annotated[Path, typer.Argument(help="Run folder (its sim.log) or a CARMEN log.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Bag to write (must not exist).")],
    fmt: Annotated[BagFmt, typer.Option("--format", help="rosbag2 (MCAP) or rosbag1.")] = (
        BagFmt.rosbag2
    ),
    as_json: Annotated[bool, typer.Option("--json", help="Print what was written as JSON.")] = (
        False
    ),
) -> None:
    """Write /scan, /odom, /tf, /tf_static, /clock and /ground_truth as a bag a ROS SLAM node
    can play unchanged (stamps: the log's own times)."""
    from worker.export.bag import export_bag

    stats = export_bag(source, out, fmt.value)
    doc = {
        "path": str(stats.path),
        "format": stats.format,
        "messages": stats.counts,
        "t_start": stats.t_start,
        "t_end": stats.t_end,
        "time_shift": stats.time_shift,
    }
    if as_json:
        print(json.dumps(doc))
        return
    topics = ", ".join(f"/{k} {n}" for k, n in stats.counts.items())
    span = f"{stats.t_start:.3f}..{stats.t_end:.3f} s"
    print(f"wrote {stats.format} bag {stats.path}: {topics} ({span})")
    if stats.time_shift:
        print(f"the log starts before t = 0: its times are shifted by +{stats.time_shift:.6f} s")
