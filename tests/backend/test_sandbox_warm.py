"""The warm-up folder of a parser process: made and removed by the API, whether the process
finished its warm-up or was stopped in the middle of it (a server stopped at once)."""

from __future__ import annotations

from backend.core.config import Settings
from backend.sandbox.manager import Sandbox


def _warm_folders(root):
    return sorted(p.name for p in root.iterdir() if p.name.startswith("mapqual-warm-"))


def test_stopped_during_its_warm_up_leaves_no_folder(tmp_path):
    box = Sandbox(Settings(MAPQUAL_SANDBOX_DIR=tmp_path), workers=2)
    box.start()
    assert len(_warm_folders(tmp_path)) == 2  # each process has its own, while it warms up
    box.shutdown()  # at once: the processes are still loading their parsers
    assert _warm_folders(tmp_path) == []


def test_a_warm_parser_keeps_no_folder(tmp_path):
    box = Sandbox(Settings(MAPQUAL_SANDBOX_DIR=tmp_path), workers=1)
    try:
        tum = b"".join(f"{i * 0.1:.1f} {i * 0.01} 0 0 0 0 0 1\n".encode() for i in range(20))
        parsed = box.run("estimate", {"a.tum": tum}, file="a.tum", topic=None)
        assert parsed is not None
        assert _warm_folders(tmp_path) == []  # the process lives on, warm, without it
    finally:
        box.shutdown()
