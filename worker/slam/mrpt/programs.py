"""MRPT's SLAM programs (Debian's mrpt-apps), run unchanged on a rawlog: their configuration,
their invocation and their output paths read back with exact time stamps."""

from __future__ import annotations

import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worker.errors import InputError, SlamFailed

CONFIG_DIRS = (Path("/usr/share/mrpt/config_files"), Path("/usr/local/share/mrpt/config_files"))
INSTALL_HINT = "install MRPT's programs: apt-get install mrpt-apps"
# the apps' display, 3D-scene and image outputs off (headless), and the per-step logs off
HEADLESS = {
    "SHOW_PROGRESS_IN_WINDOW": "0", "SHOW_PROGRESS_3D_REAL_TIME": "0", "SAVE_3D_SCENE": "0",
    "SAVE_MAP_IMAGES": "0", "LOG_FREQUENCY": "0", "SAVE_POSE_LOG": "0",
    "CAMERA_3DSCENE_FOLLOWS_ROBOT": "0", "verbosity_level": "ERROR", "rawlog_offset": "0",
}  # fmt: skip


@dataclass(frozen=True)
class MrptProgram:
    """One MRPT SLAM app: its executable and the example configuration it runs with."""

    name: str  # the algorithm's name in mapqual (mrpt_rbpf, ...)
    executable: str  # on PATH
    config: str  # under MRPT's config_files
    description: str

    def which(self) -> str:
        """The executable's path, or InputError (one line) when MRPT is not installed."""
        found = shutil.which(self.executable)
        if found is None:
            raise InputError(f"{self.name} needs MRPT's {self.executable}: {INSTALL_HINT}")
        return found

    def config_path(self) -> Path:
        for d in CONFIG_DIRS:
            if (d / self.config).is_file():
                return d / self.config
        raise InputError(f"{self.name}: MRPT's {self.config} is missing: {INSTALL_HINT}")


RBPF = MrptProgram(
    "mrpt_rbpf", "rbpf-slam", "rbpf-slam/gridmapping_RBPF_ICPbased_intel.ini",
    "MRPT rbpf-slam (third party; optimal proposal, Grisetti's method)",
)  # fmt: skip
ICP = MrptProgram(
    "mrpt_icp", "icp-slam", "icp-slam/icp-slam_demo_classic.ini",
    "MRPT icp-slam (third party; scan-to-map ICP)",
)  # fmt: skip


def configure(template: str, overrides: dict[str, str], section: str = "MappingApplication") -> str:
    """`template` (an .ini) with `overrides` set in `section`: keys present are replaced in
    place, the others added at the section's top."""
    out: list[str] = []
    current = None
    done: set[str] = set()
    for line in template.splitlines():
        stripped = line.strip()
        if stripped.startswith("[") and stripped.endswith("]"):
            current = stripped[1:-1].strip()
            out.append(line)
            if current == section:
                out.extend(f"{k}={v}" for k, v in overrides.items())
                done.update(overrides)
            continue
        key = stripped.split("=", 1)[0].strip() if "=" in stripped else None
        if current == section and key in overrides:
            continue  # set at the section's top
        out.append(line)
    if not done:
        out += [f"[{section}]"] + [f"{k}={v}" for k, v in overrides.items()]
    return "\n".join(out) + "\n"


def run_program(prog: MrptProgram, rawlog: Path, work: Path, seed: int, timeout_s: float) -> Path:
    """Run `prog` on `rawlog` in `work`; its output folder. SlamFailed (one line, with the
    program's last error line) when it crashes or runs out of time."""
    exe = prog.which()
    out_dir = work / "mrpt_out"
    settings = dict(HEADLESS, rawlog_file=str(rawlog), logOutput_dir=str(out_dir))
    if prog is RBPF:
        settings["RANDOM_SEED"] = str(seed)
    ini = work / "config.ini"
    ini.write_text(configure(prog.config_path().read_text(errors="replace"), settings))
    try:
        done = subprocess.run(
            [exe, str(ini), str(rawlog)], cwd=work, capture_output=True, text=True,
            timeout=timeout_s, stdin=subprocess.DEVNULL, check=False,
        )  # fmt: skip
    except subprocess.TimeoutExpired as exc:
        raise SlamFailed(f"{prog.executable} did not finish in {timeout_s:.0f} s") from exc
    if done.returncode != 0:
        lines = [ln for ln in (done.stderr + done.stdout).splitlines() if ln.strip()]
        last = lines[-1].strip() if lines else "no output"
        raise SlamFailed(f"{prog.executable} exited with {done.returncode}: {last[:200]}")
    return out_dir


def read_path(prog: MrptProgram, out_dir: Path, t: np.ndarray) -> np.ndarray:
    """(N, 3) the program's estimate at each of the N scans fed, in its own frame (the first
    scan at the origin), from log_estimated_path.txt: one line per action / sensory-frame pair,
    in order; rbpf-slam's lines end with the scan's time stamp, checked against `t` to 1 us."""
    path = out_dir / "log_estimated_path.txt"
    if not path.is_file():
        raise SlamFailed(f"{prog.executable} wrote no {path.name}")
    rows = np.loadtxt(path, ndmin=2)
    n = t.shape[0]
    if rows.shape[0] != n:
        raise SlamFailed(f"{prog.executable} estimated {rows.shape[0]} of the {n} scans fed")
    if not np.array_equal(rows[:, 0], np.arange(n)):
        raise SlamFailed(f"{prog.executable}'s path steps are not 0..{n - 1} in order")
    if prog is RBPF:  # step x y z yaw pitch roll t
        stamps = rows[:, 7]
        bad = np.flatnonzero(np.abs(stamps - t) > 1.5e-6)
        if bad.size:
            k = int(bad[0])
            raise SlamFailed(
                f"{prog.executable}: step {k} at t={stamps[k]:.6f}, scan at {t[k]:.6f}"
            )
        return rows[:, [1, 2, 4]]
    return rows[:, 1:4]  # icp-slam: step x y yaw
