"""`mapqual simulate`: drive a simulated robot through a floorplan and write its CARMEN log."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from mapqual.cli import app
from mapqual.cli.world import AllowOutsideOpt


class Drive(StrEnum):
    wander = "wander"
    path = "path"


class OdomModel(StrEnum):
    stage = "stage"
    gaussian = "gaussian"


WorldArg = Annotated[Path, typer.Argument(help="Image, map_server YAML or Stage .world file.")]
OutOpt = Annotated[Path, typer.Option("--out", "-o", help="Output folder.")]
SeedOpt = Annotated[int, typer.Option(help="Random seed: same seed, same bytes out.")]
DurationOpt = Annotated[float, typer.Option(help="Simulated time in seconds.")]
DriveOpt = Annotated[Drive, typer.Option(help="Reactive wanderer or waypoint follower.")]
PathOpt = Annotated[
    Path | None,
    typer.Option("--path", help="Waypoints file: `x y` in metres per line (world frame)."),
]
NoiseOpt = Annotated[
    float, typer.Option(help="Gaussian range noise sigma in metres (thesis: 0, 0.1, 0.3).")
]
OdomOpt = Annotated[OdomModel, typer.Option(help="Odometry error model.")]
ResolutionOpt = Annotated[float | None, typer.Option(help="Metres per pixel (for a bare image).")]
StartOpt = Annotated[
    tuple[float, float, float] | None,
    typer.Option(help="Start pose X Y THETA (metres, radians); default: the world's."),
]
PlotOpt = Annotated[
    bool, typer.Option(help="Also draw DIR/sim.png: paths and the last scan on the map.")
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")]


@app.command("simulate")
def simulate(
    world: WorldArg,
    out: OutOpt,
    seed: SeedOpt = 0,
    duration: DurationOpt = 600.0,
    drive: DriveOpt = Drive.wander,
    path: PathOpt = None,
    laser_noise: NoiseOpt = 0.0,
    odom_model: OdomOpt = OdomModel.stage,
    resolution: ResolutionOpt = None,
    start: StartOpt = None,
    plot: PlotOpt = False,
    as_json: JsonOpt = False,
    allow_outside: AllowOutsideOpt = False,
) -> None:
    """Simulate a robot (laser, odometry, ground truth) and write DIR/sim.log (CARMEN: ODOM,
    ROBOTLASER1, TRUEPOS), DIR/gt.tum, DIR/odom.tum and DIR/sim.json."""
    from worker.errors import InputError
    from worker.sim.drivers import read_waypoints
    from worker.sim.params import SimParams
    from worker.sim.run import run_simulation
    from worker.world import load_world

    if drive == Drive.path and path is None:
        raise InputError("--drive path needs --path FILE")
    if drive == Drive.wander and path is not None:
        raise InputError("--path is only used with --drive path")
    params = SimParams(laser_noise_sigma=laser_noise, odom_model=odom_model.value)
    waypoints = read_waypoints(path) if path is not None else None
    w = load_world(world, resolution, start_pose=start, allow_outside=allow_outside)
    result = run_simulation(
        w,
        out,
        seed=seed,
        duration_s=duration,
        drive=drive.value,
        waypoints=waypoints,
        params=params,
    )
    if plot:
        plot_run(w, out, out / "sim.png", params)
    if as_json:
        print(json.dumps(result.to_json()))
        return
    rtf = result.sim_time_s / max(result.wall_time_s, 1e-9)
    print(
        f"{result.world}: {result.n_ticks} scans over {result.sim_time_s:.1f} s simulated, "
        f"{result.distance_m:.1f} m driven, in {result.wall_time_s:.2f} s ({rtf:.0f}x real time)"
    )
    if result.path_completed is not None:
        print("path: all waypoints reached" if result.path_completed else "path: NOT completed")
    for c in result.collisions:
        print(f"collision at t = {c.t:.2f} s, x = {c.x:.3f} m, y = {c.y:.3f} m")
    for f in result.files + ((str(out / "sim.png"),) if plot else ()):
        print(f"wrote {f}")


def plot_run(world, out_dir: Path, png: Path, params) -> None:
    """Floorplan, true path (green), odometry path (red) and the last scan's endpoints."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from worker.sim.carmen import read_laser_log

    log = read_laser_log(out_dir / "sim.log")
    extent = (
        world.origin[0],
        world.origin[0] + world.width_m,
        world.origin[1],
        world.origin[1] + world.height_m,
    )
    aspect = world.height_m / world.width_m
    fig, ax = plt.subplots(figsize=(10, max(3.0, 10 * aspect)), dpi=120)
    ax.imshow(~world.occ, origin="lower", extent=extent, cmap="gray", vmin=0, vmax=1)
    ax.plot(log.pose_gt[:, 0], log.pose_gt[:, 1], color="tab:green", lw=1, label="ground truth")
    ax.plot(log.pose_odom[:, 0], log.pose_odom[:, 1], color="tab:red", lw=1, label="odometry")
    x, y, th = log.pose_gt[-1]
    r = log.ranges[-1].astype(float)
    hit = r < log.laser.range_max
    a = th + log.laser.angles
    ax.scatter(
        x + r[hit] * np.cos(a[hit]),
        y + r[hit] * np.sin(a[hit]),
        s=2,
        color="tab:blue",
        label="last scan",
        zorder=3,
    )
    ax.plot([x], [y], marker="o", color="tab:orange", ms=5)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{world.name}: {log.t[-1]:.0f} s simulated")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)
