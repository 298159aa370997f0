"""A run's report folder: summary.json, map_server map, images, relations, errors, trajectories."""

from __future__ import annotations

from pathlib import Path

from worker.evaluate.trajio import write_carmen, write_errors, write_relations, write_tum
from worker.report.plots import errors_png, map_png, trajectories_png
from worker.report.summary import RunSummary

SUMMARY = "summary.json"
SIM_LOG = "sim.log"


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
    return out
