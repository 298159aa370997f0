"""Same runs, same files? Runs a set of short runs in this checkout and in another one and
compares their report folders file by file (the refactoring proof of issue 16).

    python benchmarks/compare_reports.py --against /work/head
    python benchmarks/compare_reports.py --against /work/head --worlds office_a,office_d \
        --slam rbpf,odometry --seeds 1-3 --time-limit 90

Each checkout runs with its own `.venv/bin/mapqual run` and a throwaway SQLite database. Files
are compared byte for byte, except what measures the wall clock and cannot repeat:
`summary.json`'s wall-clock timings (`*_wall_s`, `wall_time_s`, `real_time_factor`) are masked
in the text before the comparison (so key order and number formatting still count), and a zip
is compared member by member (its member timestamps are the wall clock too). With
`--allow-new-params`, parameters that this checkout stores and the other does not (a setting
that was a constant in the code before) are listed, not counted as a difference: the rest of
summary.json must still match, key order included. With `--params-as-read`, the other
checkout's stored params are read by this checkout's `RunParams.from_json` and written back
before the comparison (a new stored layout of the same settings: issue 53's grouped `explore`).
Prints one line per run and a summary; exit
0 when every run's folder matches, 1 when one differs, 2 on bad input.
"""

from __future__ import annotations

import argparse
import io
import json
import re
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
WORLDS = "office_a,office_d,office_g_furnitures,lab_a_scan"
WALL = re.compile(rb'("(?:[a-z_]*_wall_s|wall_time_s|real_time_factor)":\s*)[-+0-9.eE]+')


def masked(name: str, data: bytes) -> bytes:
    """The bytes of a report file with the wall-clock figures masked (summary.json only)."""
    return WALL.sub(rb"\1null", data) if name.endswith("summary.json") else data


def zip_members(data: bytes) -> dict[str, bytes]:
    """A zip's members by name, each masked as a file of that name would be."""
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return {n: masked(n, z.read(n)) for n in sorted(z.namelist())}


def _prune(this: dict, that: dict, where: str, added: list[str]) -> dict:
    """`this` without the keys `that` lacks (recursively), their dotted names put in `added`."""
    out = {}
    for k, v in this.items():
        if k not in that:
            added.append(f"{where}{k}")
        elif isinstance(v, dict) and isinstance(that[k], dict):
            out[k] = _prune(v, that[k], f"{where}{k}.", added)
        else:
            out[k] = v
    return out


def same_summary(da: bytes, db: bytes, added: list[str], as_read: bool = False) -> bool:
    """summary.json alike but for the parameters only `da` has (listed in `added`); as_read:
    `db`'s params as this checkout reads and stores them."""
    a, b = (json.loads(masked("summary.json", d)) for d in (da, db))
    if as_read:
        sys.path.insert(0, str(HERE))
        from worker.run_params import RunParams

        b["params"] = RunParams.from_json(b["params"]).to_json()
    a["params"] = _prune(a.get("params", {}), b.get("params", {}), "params.", added)
    return json.dumps(a) == json.dumps(b)


def compare_folders(
    a: Path, b: Path, new_params: list[str] | None = None, as_read: bool = False
) -> list[str]:
    """Differences between report folders a and b, one line each (empty when they match);
    with `new_params` (a list), summary.json parameters only `a` has are put there instead."""
    names_a = {p.relative_to(a).as_posix() for p in a.rglob("*") if p.is_file()}
    names_b = {p.relative_to(b).as_posix() for p in b.rglob("*") if p.is_file()}
    diffs = [f"only in {a}: {n}" for n in sorted(names_a - names_b)]
    diffs += [f"only in {b}: {n}" for n in sorted(names_b - names_a)]
    for n in sorted(names_a & names_b):
        da, db = (a / n).read_bytes(), (b / n).read_bytes()
        if n.endswith(".zip"):
            za, zb = zip_members(da), zip_members(db)
            if za != zb:
                bad = sorted(k for k in za.keys() | zb.keys() if za.get(k) != zb.get(k))
                diffs.append(f"differs: {n} (members {', '.join(bad)})")
        elif n.endswith("summary.json") and (new_params is not None or as_read):
            if not same_summary(da, db, [] if new_params is None else new_params, as_read):
                diffs.append(f"differs: {n} (beyond the parameters only this checkout stores)")
        elif masked(n, da) != masked(n, db):
            diffs.append(f"differs: {n} ({len(da)} against {len(db)} bytes)")
    return diffs


def seeds_of(text: str) -> list[int]:
    """'1-3' or '1,4,7' -> the seeds."""
    if "-" in text:
        lo, hi = (int(v) for v in text.split("-", 1))
        return list(range(lo, hi + 1))
    return [int(v) for v in text.split(",")]


def world_path(checkout: Path, name: str) -> Path:
    """A bundled world by name (worlds/bormann/NAME.yaml or its furniture/ variant)."""
    for p in (checkout / "worlds").rglob(f"{name}.yaml"):
        return p
    raise SystemExit(f"error: no world {name!r} under {checkout}/worlds")


def one_run(checkout: Path, world: str, slam: str, seed: int, limit: float, out: Path) -> float:
    """`mapqual run` in `checkout` into `out`; returns the wall time [s]."""
    exe = checkout / ".venv" / "bin" / "mapqual"
    db = out.parent / f"{out.name}.db"
    cmd = [str(exe), "run", str(world_path(checkout, world)), "--seed", str(seed)]
    cmd += ["--slam", slam, "--time-limit", str(limit), "-o", str(out)]
    env = {"DATABASE_URL": f"sqlite:///{db}", "PATH": "/usr/bin:/bin", "HOME": str(Path.home())}
    env["NUMBA_NUM_THREADS"] = "1"
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=checkout, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:]
        raise SystemExit(f"error: {checkout}: {' '.join(cmd[1:])} failed: {' '.join(tail)}")
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", required=True, type=Path, help="the other checkout")
    ap.add_argument("--worlds", default=WORLDS, help="bundled world names, comma-separated")
    ap.add_argument("--slam", default="rbpf,odometry")
    ap.add_argument("--seeds", default="1-3")
    ap.add_argument("--time-limit", type=float, default=90.0, help="[s] simulated, per run")
    ap.add_argument("--keep", type=Path, help="keep the report folders here")
    ap.add_argument(
        "--allow-new-params", action="store_true",
        help="list parameters only this checkout stores instead of counting them as differences",
    )  # fmt: skip
    ap.add_argument(
        "--params-as-read", action="store_true",
        help="read the other checkout's stored params with this checkout's RunParams first",
    )  # fmt: skip
    args = ap.parse_args()
    other = args.against.resolve()
    for c in (HERE, other):
        if not (c / ".venv" / "bin" / "mapqual").exists():
            print(f"error: {c} has no .venv/bin/mapqual", file=sys.stderr)
            return 2
    root = args.keep or Path(tempfile.mkdtemp(prefix="compare_reports_"))
    cases = [
        (w, s, seed)
        for w in args.worlds.split(",")
        for s in args.slam.split(",")
        for seed in seeds_of(args.seeds)
    ]
    failed = 0
    for i, (w, s, seed) in enumerate(cases, 1):
        key = f"{w}-{s}-{seed}"
        t_this = one_run(HERE, w, s, seed, args.time_limit, root / "this" / key)
        t_that = one_run(other, w, s, seed, args.time_limit, root / "that" / key)
        new: list[str] | None = [] if args.allow_new_params else None
        diffs = compare_folders(root / "this" / key, root / "that" / key, new, args.params_as_read)
        n = sum(1 for p in (root / "this" / key).rglob("*") if p.is_file())
        state = "same" if not diffs else f"{len(diffs)} differences"
        print(f"[{i}/{len(cases)}] {key}: {n} files, {state} ({t_this:.0f} s / {t_that:.0f} s)")
        for d in diffs:
            print(f"    {d}")
        if new:
            print(f"    parameters only this checkout stores: {', '.join(sorted(set(new)))}")
        failed += bool(diffs)
    print(f"{len(cases) - failed} of {len(cases)} runs give the same report folder; in {root}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
