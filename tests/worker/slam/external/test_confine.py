"""An external program's confinement: its environment holds no secret, it cannot allocate
without bound, and its whole tree ends with it, a grandchild that called setsid included."""

from __future__ import annotations

import os
import sys
import textwrap
import time
from pathlib import Path

import pytest

from worker.slam.external.confine import program_env
from worker.slam.external.process import ChildProcess

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="Linux process controls")


def _alive(pid: int) -> bool:
    """Running (a zombie or a vanished pid is not)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


def _program(tmp_path: Path, body: str) -> list[str]:
    path = tmp_path / "prog.py"
    path.write_text(textwrap.dedent(body))
    return [sys.executable, str(path)]


def _wait_for(path: Path, timeout: float = 10.0) -> str:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.is_file() and path.read_text().endswith("\n"):
            return path.read_text()
        time.sleep(0.02)
    raise AssertionError(f"{path.name} was not written")


def test_the_environment_is_allow_listed():
    env = {
        "PATH": "/usr/bin", "HOME": "/home/w", "LC_ALL": "C", "ROS_DISTRO": "jazzy",
        "DATABASE_URL": "postgresql://u:pw@db/x", "REDIS_URL": "redis://r",
        "MAPQUAL_SECRET_KEY": "s3", "ROS_SECRET_TOKEN": "t", "AWS_SECRET_ACCESS_KEY": "a",
        "CELERY_BROKER_URL": "amqp://", "RANDOM": "x",
    }  # fmt: skip
    assert program_env(env) == {
        "PATH": "/usr/bin", "HOME": "/home/w", "LC_ALL": "C", "ROS_DISTRO": "jazzy",
    }  # fmt: skip


def test_the_program_sees_no_secret(tmp_path: Path, monkeypatch):
    monkeypatch.setenv("DATABASE_URL", "postgresql://u:pw@db/x")
    monkeypatch.setenv("MAPQUAL_SECRET_KEY", "s3cr3t")
    out = tmp_path / "env.txt"
    cmd = _program(
        tmp_path,
        f"""
        import os
        open({str(out)!r}, "w").write(repr(sorted(os.environ)) + "\\n")
        """,
    )
    child = ChildProcess(cmd)
    seen = _wait_for(out)
    child.close(5.0)
    assert "DATABASE_URL" not in seen and "MAPQUAL_SECRET_KEY" not in seen and "PATH" in seen


def test_a_setsid_grandchild_ends_with_the_program(tmp_path: Path):
    pids = tmp_path / "pids.txt"
    cmd = _program(
        tmp_path,
        f"""
        import os, time
        if os.fork() == 0:          # the child leaves the session, then forks the grandchild
            os.setsid()
            if os.fork() == 0:
                open({str(pids)!r}, "w").write(f"{{os.getpid()}}\\n")
                while True:
                    time.sleep(1)
            os._exit(0)             # the grandchild is an orphan now
        while True:
            time.sleep(1)
        """,
    )
    child = ChildProcess(cmd)
    grandchild = int(_wait_for(pids))
    assert _alive(grandchild) and os.getsid(grandchild) != os.getsid(child.pid)
    child.close(0.5)
    end = time.monotonic() + 5
    while _alive(grandchild) and time.monotonic() < end:
        time.sleep(0.05)
    assert not _alive(grandchild)


def test_a_program_that_allocates_without_bound_is_stopped(tmp_path: Path):
    cmd = _program(
        tmp_path,
        """
        blocks = []
        while True:
            blocks.append(bytearray(16 << 20))
        """,
    )
    t0 = time.monotonic()
    child = ChildProcess(cmd, memory_mb=300)
    code = child.proc.wait(timeout=30)
    child.close(1.0)
    assert code != 0 and time.monotonic() - t0 < 30
    assert "MemoryError" in child.stderr_tail()


def test_a_program_that_spins_is_stopped_by_its_cpu_limit(tmp_path: Path):
    cmd = _program(
        tmp_path,
        """
        while True:
            pass
        """,
    )
    child = ChildProcess(cmd, cpu_s=1)
    code = child.proc.wait(timeout=30)
    child.close(1.0)
    assert code < 0  # SIGXCPU, then SIGKILL at the hard limit
