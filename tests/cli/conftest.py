"""The CLI tests' shared fixture: `run(*argv)` calls `mapqual` in process and returns (exit code,
stdout, stderr)."""

from __future__ import annotations

import sys

import pytest

from mapqual.cli import main


@pytest.fixture
def run(monkeypatch, capsys):
    # `mapqual run` sets it for its process (its share of the cores): restored after the test
    monkeypatch.delenv("MAPQUAL_SLAM_THREADS", raising=False)

    def _run(*argv) -> tuple[int, str, str]:
        monkeypatch.setattr(sys, "argv", ["mapqual", *map(str, argv)])
        try:
            main()
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        out, err = capsys.readouterr()
        return code, out, err

    return _run
