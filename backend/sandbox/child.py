"""The sandbox's processes: a zygote that loads the parsers (or the world analysis) once, and
per task a forked child that limits itself, runs the task and writes a typed result.

The zygote is started by `backend.sandbox.manager` with an allow-listed environment (no database or
broker URL, no secret key). Each child works in a temporary folder of its own (`in/` the
uploaded files, `out/` the result, `tmp/` its TMPDIR), in a session of its own, and sets its
hard limits before it reads a byte of the upload: address space, CPU seconds, bytes a file
may grow to, open files, no core dumps; and the decompression budget. The result is
`out/result.json` ({"ok": true, ...} or {"ok": false, "kind": ..., "error": one line}) and,
for an estimate, `out/trajectory.npy` (N x 4 float64: t, x, y, yaw); for a floorplan,
`out/result.bin` (`worker.world.floorplan`). The tasks are `backend.sandbox.tasks`'.
"""

from __future__ import annotations

import errno
import json
import os
import resource
import signal
import sys
from pathlib import Path
from typing import Any

MiB = 1 << 20


def limit_self(limits: dict[str, int]) -> None:
    """Hard limits on this process (soft = hard: nothing in here may raise them again)."""
    cpu = int(limits["cpu_s"])
    for rlimit, value in (
        (resource.RLIMIT_AS, int(limits["memory_mb"]) * MiB),
        (resource.RLIMIT_CPU, cpu),
        (resource.RLIMIT_FSIZE, int(limits["temp_mb"]) * MiB),
        (resource.RLIMIT_NOFILE, int(limits["open_files"])),
        (resource.RLIMIT_CORE, 0),
    ):
        resource.setrlimit(rlimit, (value, value))
    # Python ignores SIGXFSZ (a write past RLIMIT_FSIZE fails with EFBIG, which a parser may
    # take for a damaged file); by default it ends the process, which the API reports.
    signal.signal(signal.SIGXFSZ, signal.SIG_DFL)


def run(req: dict[str, Any]) -> dict[str, Any]:
    """The task's outcome as the result's JSON (every failure a one-line reason)."""
    from backend.sandbox.tasks import TASKS
    from worker.decompress_budget import set_budget
    from worker.errors import InputError
    from worker.export.bounded import bound_bag_readers
    from worker.world.image_io import ImageTooLarge

    set_budget(int(req["unpacked_bytes"]))
    try:
        if req["task"] == "estimate":
            bound_bag_readers()
        return {"ok": True, **TASKS[req["task"]](req)}
    except ImageTooLarge as exc:
        return {"ok": False, "kind": "too_large", "error": str(exc)}
    except InputError as exc:
        return {"ok": False, "kind": "input", "error": str(exc)}
    except MemoryError:
        return {"ok": False, "kind": "memory", "error": ""}
    except OSError as exc:
        if exc.errno == errno.ENOMEM:  # a read or a mapping refused at the address-space limit
            return {"ok": False, "kind": "memory", "error": ""}
        return {"ok": False, "kind": "input", "error": f"cannot be read ({type(exc).__name__})"}
    except RecursionError:
        return {"ok": False, "kind": "input", "error": "nested too deeply to be read"}
    except Exception as exc:  # noqa: BLE001 - a hostile file fails deep in a parser
        return {"ok": False, "kind": "input", "error": f"cannot be read ({type(exc).__name__})"}


def serve(work: Path) -> int:
    """In a forked child: read the request in `work`, limit this process, run the task,
    write the result. Its exit code."""
    devnull = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):  # the zygote's pipes to the API are not the parser's to write
        os.dup2(devnull, fd)
    os.chdir(work)
    req = json.loads(Path("request.json").read_text())
    limit_self(req["limits"])
    os.environ["TMPDIR"] = str(work / "tmp")
    import tempfile

    tempfile.tempdir = None  # read TMPDIR again: the parser's own folder
    os.chdir("in")
    out = run(req)
    Path("../out/result.json").write_text(json.dumps(out))
    return 0


def zygote(kind: str, warm: str) -> int:
    """Serve requests from the API, one at a time: a line {"work": folder} in, a forked child
    serves it; lines {"pid": ...} then {"status": exit code (negative: a signal), "cpu_s": its
    CPU time} out. `kind`:
    which code it loads first ("sandbox": the upload parsers, "analysis": world analysis),
    trying it on tiny inputs written to the folder `warm`."""
    from backend.sandbox.tasks import warm_up

    warm_up(kind, Path(warm))
    out = sys.stdout.buffer
    out.write(b'{"ready": true}\n')
    out.flush()
    for line in sys.stdin.buffer:
        work = Path(json.loads(line)["work"])
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child, measured by the API's tests
            code = 70
            try:
                os.setsid()
                code = serve(work)
            finally:
                os._exit(code)
        out.write(json.dumps({"pid": pid}).encode() + b"\n")
        out.flush()
        _, st, usage = os.wait4(pid, 0)
        cpu = usage.ru_utime + usage.ru_stime
        done = {"status": os.waitstatus_to_exitcode(st), "cpu_s": cpu}
        out.write(json.dumps(done).encode() + b"\n")
        out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(zygote(sys.argv[1], sys.argv[2]))
