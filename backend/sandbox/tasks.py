"""What the sandbox's children do (`backend.sandbox.child`), by task, and how each kind of
zygote warms up. Every task runs in a forked child that has limited itself, in its folder's
`in/`; it writes `../out/result.bin` or `../out/trajectory.npy` and returns the facts of
`out/result.json`.

- reading uploads ("sandbox" zygotes): `estimate` (an estimate in any format) and
  `floorplan` (a world's files read into a `Floorplan`: images decoded, YAML or Stage parsed;
  a plan of at most ANALYSE_AT_ONCE pixels analysed there too);
- analysing worlds ("analysis" zygotes): `world` (a floorplan's regions, clearance, start
  pose and facts) and `predict` (its features and the bundled model's prediction).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any


def estimate(req: dict[str, Any]) -> dict[str, Any]:
    import numpy as np

    from worker.export.untrusted import read_upload_estimate

    est = read_upload_estimate(Path(req["file"]), req.get("topic"), req["unpacked_bytes"])
    t = np.asarray(est.t, np.float64)
    data = np.column_stack([t, np.asarray(est.poses, np.float64).reshape(len(t), 3)])
    np.save(Path("../out/trajectory.npy"), data, allow_pickle=False)
    return {"n": int(len(t))}


ANALYSE_AT_ONCE = 2_000_000  # [pixels] a plan this small is analysed where it was read


def floorplan(req: dict[str, Any]) -> dict[str, Any]:
    """The upload read into a Floorplan's bytes; a small plan analysed here too (a fraction
    of a second), which spares its world a second process."""
    from worker.errors import InputError
    from worker.world.floorplan import pack_floorplan
    from worker.world.loader import build_world, read_floorplan

    plan = read_floorplan(Path(req["file"]), req.get("resolution"), max_pixels=req["max_pixels"])
    Path("../out/result.bin").write_bytes(pack_floorplan(plan))
    if plan.occ.size > ANALYSE_AT_ONCE:
        return {}
    try:
        return {"analysis": _facts(build_world(plan))}
    except InputError as exc:  # the world will be invalid for it (the upload is stored)
        return {"analysis": {"error": str(exc)}}


def _plan(req: dict[str, Any]):
    """The floorplan in `file` (`pack_floorplan`'s bytes, made by a sandbox that read the
    upload), every field checked."""
    from worker.world.floorplan import unpack_floorplan

    return unpack_floorplan(Path(req["file"]).read_bytes(), req["max_pixels"])


def world(req: dict[str, Any]) -> dict[str, Any]:
    from worker.world.loader import build_world

    return _facts(build_world(_plan(req)))


def _facts(w) -> dict[str, Any]:
    """What the API stores of an analysed World besides its floorplan."""
    return {
        "start_pose": [float(v) for v in w.start_pose],
        "facts": dataclasses.asdict(w.facts),
        "warnings": list(w.warnings),
    }


def predict(req: dict[str, Any]) -> dict[str, Any]:
    from worker.predict.service import predict_world
    from worker.world.world import World

    plan = _plan(req)
    w = World.from_array(
        plan.occ, plan.resolution, plan.origin, plan.start_pose, plan.name, n_rooms=plan.n_rooms
    )
    return {"prediction": predict_world(w, req["slam"])}


TASKS = {"estimate": estimate, "floorplan": floorplan, "world": world, "predict": predict}


def warm_up(kind: str, tmp: Path) -> None:
    """Import the kind's code and run it once on a tiny input written to the folder `tmp`, so
    that forked children start with everything loaded and compiled (numba kernels included)."""
    import numpy as np

    if kind == "analysis":  # the `world` and `predict` tasks' own path
        from worker.predict.service import predict_world
        from worker.world.floorplan import Floorplan, pack_floorplan
        from worker.world.world import World

        occ = np.zeros((62, 102), bool)  # a 3 m x 5 m room
        occ[[0, -1], :] = True
        occ[:, [0, -1]] = True
        plan = Path(tmp) / "warm.bin"
        plan.write_bytes(pack_floorplan(Floorplan("warm", occ, 0.05, (0, 0), None, None,
                                                  (), "warm.png")))  # fmt: skip
        world({"file": str(plan), "max_pixels": occ.size})
        predict_world(World.from_array(occ, 0.05, name="warm"))
        return
    from PIL import Image

    from worker.export.bounded import bound_bag_readers
    from worker.export.untrusted import read_upload_estimate
    from worker.world.loader import read_floorplan

    bound_bag_readers()
    tum = Path(tmp) / "warm.tum"
    lines = [f"{i * 0.1:.1f} {i * 0.01} 0 0 0 0 0 1" for i in range(50)]
    tum.write_text("\n".join(lines) + "\n")
    est = read_upload_estimate(tum, None, 1 << 20)
    np.column_stack([est.t, est.poses])
    png = Path(tmp) / "warm.png"
    Image.fromarray(np.full((8, 8), 255, np.uint8)).save(png)
    read_floorplan(png, 0.05, max_pixels=1000)
