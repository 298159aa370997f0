"""The shell commands of a manual page, shortened to run in a test, and a runner for them.

Every line of a page's ```sh blocks is run as written, but for the substitutions below that
make long runs short (simulated time, seeds); lines that need what a test machine does not
have (ROS, evo, the install itself) are skipped, each for a stated reason.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
SHORT_S = 10  # [s] simulated time of every run and simulation a tutorial makes

# (pattern, replacement): the short version of a command
SHORTEN = [
    (re.compile(r"--time-limit \d+"), f"--time-limit {SHORT_S}"),
    (re.compile(r"--duration \d+"), f"--duration {SHORT_S}"),
    (re.compile(r"--seeds 1-\d+"), "--seeds 1-2"),
]
# how a line starts -> why it is not run here
SKIP = {
    "ros2 ": "needs a ROS 2 installation (the test records the bag itself)",
    "rosbag ": "needs ROS 1",
    "rosparam ": "needs ROS 1",
    "evo_ape ": "evo's command line: a dev dependency, not the product",
    "python3 -m venv ": "the install itself (the test runs inside an installed environment)",
    ". .venv/bin/activate": "activating the environment (the test puts it first on PATH)",
}


@dataclass(frozen=True)
class Command:
    line: str  # as the page writes it (continuations joined)
    run: str  # what the test runs


def page_commands(page: str) -> list[Command]:
    """Every command of the page's ```sh blocks, with its short version."""
    text = (DOCS / page).read_text()
    out = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = re.sub(r"\s+", " ", line).strip()
            if not line or line.startswith("#"):
                continue
            if line.startswith(tuple(SKIP)):
                continue
            out.append(Command(line, _shorten(line)))
    return out


def _shorten(line: str) -> str:
    for pattern, repl in SHORTEN:
        line = pattern.sub(repl, line)
    if re.match(r"mapqual (run|batch) ", line) and "--time-limit" not in line:
        # before a redirection or a comment, if any
        head, sep, tail = (re.split(r"( [>#] )", line, maxsplit=1) + ["", ""])[:3]
        line = f"{head} --time-limit {SHORT_S}{sep}{tail}"
    return line


def environment(workdir: Path) -> dict[str, str]:
    """This interpreter's environment first on PATH (as `. .venv/bin/activate` does), and a
    database and runs folder of the test's own."""
    bin_dir = str(Path(sys.executable).parent)
    return {
        **os.environ,
        "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}",
        "DATABASE_URL": f"sqlite:///{workdir / 'mapqual.db'}",
        "MAPQUAL_RUNS_DIR": str(workdir / "runs"),
        "MPLBACKEND": "Agg",
    }


def workspace(tmp: Path) -> Path:
    """A working folder with the repository's worlds/ and examples/ as a clone has them."""
    for name in ("worlds", "examples"):
        (tmp / name).symlink_to(ROOT / name, target_is_directory=True)
    return tmp


def run(command: Command, workdir: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run one command in bash (pages use `>`), failing with its output when it fails."""
    # its own session, so that a timeout ends the command's children too (mapqual under bash)
    proc = subprocess.Popen(
        ["bash", "-c", command.run], cwd=workdir, env=environment(workdir),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    done = subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)
    assert done.returncode == 0, (
        f"`{command.line}` (run as `{command.run}`) exited {done.returncode}:\n"
        f"{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    )
    return done
