"""`mapqual users add` prints a working key on its last line; names are unique."""

from __future__ import annotations

import os
import subprocess
import sys

from backend.db.session import session_scope
from backend.store import user_for_key


def _mapqual(tmp_path, *args):
    env = dict(os.environ, DATABASE_URL=f"sqlite:///{tmp_path / 'm.db'}")
    return subprocess.run(
        [sys.executable, "-m", "mapqual", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=120,
    )


def test_users_add_prints_a_key_that_signs_in_as_that_user(tmp_path):
    r = _mapqual(tmp_path, "users", "add", "carol", "--admin")
    assert r.returncode == 0, r.stderr
    key = r.stdout.strip().splitlines()[-1]
    with session_scope(f"sqlite:///{tmp_path / 'm.db'}") as s:
        user = user_for_key(s, key)
        assert user is not None and user.name == "carol" and user.is_admin


def test_duplicate_and_reserved_names_are_refused_with_one_line(tmp_path):
    assert _mapqual(tmp_path, "users", "add", "dave").returncode == 0
    for name, needle in (("dave", "exists already"), ("local", "reserved")):
        r = _mapqual(tmp_path, "users", "add", name)
        assert r.returncode == 2
        assert len(r.stderr.strip().splitlines()) == 1 and needle in r.stderr
