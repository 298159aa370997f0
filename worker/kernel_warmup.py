"""The child process of `worker.kernel_cache.warm_kernels`: `python -m worker.kernel_warmup
ALGORITHM` runs a short run that compiles the kernels of a run of ALGORITHM into numba's
on-disk cache, and exits."""

from __future__ import annotations

import sys
from pathlib import Path

WARM_S = 60.0  # [s] simulated: past the first whole-map read (full_map_check_period, 30 s)


def warm_up_run(algorithm: str) -> None:
    """The child's work: WARM_S simulated of `algorithm` on a 30 m x 30 m hospital wing, its
    world loaded from a map_server file as a user's is, its CARMEN log written, evaluated and
    scored."""
    import dataclasses
    import tempfile

    from worker.pipeline import run_one
    from worker.run_params import RunParams
    from worker.world.generate import BuildingSpec, generate, write_world
    from worker.world.loader import load_world

    spec = BuildingSpec(kind="hospital", width_m=30.0, height_m=30.0, seed=1)
    params = RunParams(algorithm=algorithm)
    params = dataclasses.replace(
        params, explore=dataclasses.replace(params.explore, time_limit=WARM_S)
    )
    with tempfile.TemporaryDirectory(prefix="mapqual_warm_") as tmp:
        world = load_world(write_world(generate(spec), spec, Path(tmp), "warm"))
        run_one(world, params, seed=1, on_progress=lambda p: None, sim_log=Path(tmp) / "sim.log")


if __name__ == "__main__":
    warm_up_run(sys.argv[1])
