"""A run's report folder: summary.json, map_server map, images, relations, errors, trajectories."""

from __future__ import annotations

import os
import secrets
import zipfile
from pathlib import Path

from worker.evaluate.trajectory import Trajectory
from worker.evaluate.trajio import write_carmen, write_errors, write_relations, write_tum
from worker.report.plots import errors_png, map_png, overlay_png, trajectories_png
from worker.report.summary import RunSummary
from worker.report.timeline import TIMELINE

SUMMARY = "summary.json"
SIM_LOG = "sim.log"
REPORT_ZIP = "report.zip"  # the whole folder as one download, made once the report is written


def error_lines(summary: RunSummary) -> list[str]:
    """The B errors as the thesis printed them on the map (Fig. 5.3)."""
    b = summary.relation("B")
    if b is None:
        return [f"{summary.world} seed {summary.seed}: no B relations evaluated"]
    t, r = b.translation, b.rotation
    return [
        f"trans. error: mean {t.mean:.3f} m, std {t.std:.3f} m",
        f"rot. error: mean {r.mean:.4f} rad, std {r.std:.4f} rad",
        f"{t.n} B relations; {summary.outcome}, coverage {summary.coverage:.0%}",
    ]


def map_score_lines(summary: RunSummary) -> list[str]:
    """The map-versus-floorplan score as written on the overlay."""
    m = summary.map_score
    if m is None:
        return []

    def f(v: float | None, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    return [
        f"wall distance {f(m.distance_m, '.3f')} m (map->plan {f(m.distance_map_m, '.3f')}, "
        f"plan->map {f(m.distance_floorplan_m, '.3f')})",
        f"precision {f(m.precision, '.2f')}, recall {f(m.recall, '.2f')} "
        f"(within {m.tolerance_m:g} m); free share {m.free_share:.0%}",
    ]


def write_report(result, out_dir: str | Path) -> Path:
    """Write every report file of `result` (a `worker.pipeline.RunResult`) into `out_dir`.

    `sim.log` is written during the run by `run_one(..., sim_log=out_dir / "sim.log")`.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ex, summary = result.exploration, result.summary
    (out / SUMMARY).write_text(summary.to_json_text())
    ex.final_map.save_map_server(out / "map")
    map_png(out / "map.png", ex.final_map.to_ros(), error_lines(summary))
    world = result.world
    title = f"{world.name}, seed {result.seed}, {summary.algorithm}: {summary.outcome}"
    if summary.reason:
        title += f" ({summary.reason})"
    trajectories_png(
        out / "trajectories.png", world.occ, world.resolution, world.origin,
        ex.pose_gt, ex.pose_est, title,
    )  # fmt: skip
    score = getattr(result, "map_score", None)
    if score is not None:
        overlay_png(out / "map_overlay.png", score.floorplan_walls, score.map_walls_xy,
                    world.resolution, world.origin, map_score_lines(summary))  # fmt: skip
    timeline = getattr(result, "timeline", None)
    if timeline:  # coverage against simulated time, for the viewer's replay
        timeline.write(out / TIMELINE)
    for kind, rel in result.relations.items():
        write_relations(out / f"relations_{kind}.txt", rel)
    if "B" in result.errors:
        b = result.errors["B"]
        ok = b.evaluated
        write_errors(out / "T.errors", b.t1[ok], b.t2[ok], b.translation[ok])
        write_errors(out / "R.errors", b.t1[ok], b.t2[ok], b.rotation[ok])
        errors_png(out / "errors.png", b.t2[ok], b.translation[ok], b.rotation[ok])
    write_carmen(out / "gt.log", result.gt)
    write_carmen(out / "est.log", result.est)
    write_tum(out / "gt.tum", result.gt)
    write_tum(out / "est.tum", result.est)
    if ex.pose_final is not None:  # the SLAM's final trajectory, where it keeps one
        write_tum(out / "est_final.tum", Trajectory(ex.t, ex.pose_final))
    return out


def write_report_zip(folder: str | Path, arc_root: str, dest: Path | None = None) -> Path:
    """Zip every file of the report `folder` (but the zip itself) as `arc_root/<path>` into
    `dest` (default `folder/report.zip`): written under a temporary name and renamed, so that
    a reader (or a racing writer) sees a whole zip or none."""
    folder = Path(folder)
    dest = folder / REPORT_ZIP if dest is None else Path(dest)
    files = [p for p in sorted(folder.rglob("*")) if p.is_file() and not _zip_own(p, folder)]
    tmp = dest.with_name(f".{REPORT_ZIP}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
            for path in files:
                zf.write(path, f"{arc_root}/{path.relative_to(folder).as_posix()}")
        os.replace(tmp, dest)
    finally:
        tmp.unlink(missing_ok=True)
    return dest


def _zip_own(path: Path, folder: Path) -> bool:
    """The zip, or a zip being written, at the top of the folder."""
    if path.parent != folder:
        return False
    return path.name == REPORT_ZIP or (
        path.name.startswith(f".{REPORT_ZIP}.") and path.name.endswith(".tmp")
    )
