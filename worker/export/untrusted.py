"""Estimates from strangers: a rosbag2 zip unpacked with every byte counted, SQLite storage
files inspected read-only under a deadline, compressed rosbag2 refused, then `read_estimate`.

Meant to run in the upload sandbox (`backend.sandbox.manager`), whose process limits catch what
these checks do not foresee; the checks turn the foreseen attacks into one-line reasons.
"""

from __future__ import annotations

import re
import sqlite3
import time
import zipfile
import zlib
from pathlib import Path
from urllib.parse import quote

from worker.errors import InputError
from worker.evaluate.trajectory import Trajectory

ZIP_MAX_MEMBERS = 64  # a rosbag2 directory: metadata.yaml and a few storage files
ZIP_METHODS = {zipfile.ZIP_STORED: "stored", zipfile.ZIP_DEFLATED: "deflated"}
_FILE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,120}$")
SQLITE_STEPS = 10_000  # virtual-machine steps between looks at the SQLite deadline
SQLITE_DEADLINE_S = 5.0  # [s] to inspect one storage file's schema
META_MAX = 1 << 20  # [bytes] of metadata.yaml (ros2 bag writes a few kB; YAML parsing is slow)


def unzip_rosbag2(src: Path, folder: Path, max_bytes: int) -> Path:
    """The rosbag2 directory in the zip `src`, unpacked into `folder`/bag: members stored or
    deflated only, beside one metadata.yaml, at most `max_bytes` unpacked in all (counted as
    they stream out, whatever the zip's index declares)."""
    try:
        with zipfile.ZipFile(src) as zf:
            infos = [i for i in zf.infolist() if not i.is_dir()]
            if not infos or len(infos) > ZIP_MAX_MEMBERS:
                raise InputError(f"a rosbag2 zip holds 1 to {ZIP_MAX_MEMBERS} files")
            base = _base(infos)
            out = folder / "bag"
            out.mkdir()
            left = max_bytes
            for info in infos:
                left -= _extract(zf, info, base, out, left)
            return out
    except InputError:
        raise
    except (zipfile.BadZipFile, RuntimeError, ValueError, EOFError, OSError, zlib.error):
        # a damaged zip, an encrypted member, a bad CRC
        raise InputError("not a readable zip file") from None


def _base(infos: list[zipfile.ZipInfo]) -> Path:
    metas = [i for i in infos if Path(i.filename).name == "metadata.yaml"]
    if len(metas) != 1:
        raise InputError("a rosbag2 zip holds exactly one metadata.yaml")
    return Path(metas[0].filename).parent


def _extract(zf: zipfile.ZipFile, info: zipfile.ZipInfo, base: Path, out: Path, left: int) -> int:
    """Write one member into `out`; the bytes it unpacked to."""
    rel = Path(info.filename)
    if rel.is_absolute() or ".." in rel.parts or rel.parent != base:
        raise InputError(f"zip member {info.filename!r}: not beside metadata.yaml")
    if not _FILE_NAME.match(rel.name):
        raise InputError(f"zip member {info.filename!r}: unsafe file name")
    if info.compress_type not in ZIP_METHODS:
        raise InputError(
            f"zip member {info.filename!r}: compression method {info.compress_type} is not "
            "accepted (zip the bag with stored or deflated members, as `zip` does)"
        )
    if info.flag_bits & 0x1:
        raise InputError(f"zip member {info.filename!r} is encrypted")
    written = 0
    with zf.open(info) as src, (out / rel.name).open("wb") as dst:
        while piece := src.read(min(1 << 20, left - written + 1)):
            written += len(piece)
            if written > left:
                raise InputError(
                    "the zip unpacks to more than the limit for an upload "
                    "(setting upload_unpacked_mb, environment MAPQUAL_UPLOAD_UNPACKED_MB)"
                )
            dst.write(piece)
    return written


def check_rosbag2(folder: Path) -> None:
    """Refuse a compressed rosbag2 (file or message compression) and storage files that are
    not plain SQLite tables."""
    meta = folder / "metadata.yaml"
    if meta.is_file() and meta.stat().st_size > META_MAX:
        raise InputError(
            f"metadata.yaml holds {meta.stat().st_size} bytes: a rosbag2's holds a few kB "
            f"(at most {META_MAX} accepted)"
        )
    if meta.is_file():
        text = meta.read_text(encoding="utf-8", errors="replace")
        mode = re.search(r"^\s*compression_mode:\s*['\"]?(\w*)", text, re.MULTILINE)
        if mode and mode.group(1).lower() not in ("", "none"):
            raise InputError(
                f"rosbag2 compression_mode {mode.group(1)!r} is not accepted: upload the bag "
                "uncompressed (ros2 bag convert), or as MCAP with chunk compression"
            )
    for db in sorted(folder.glob("*.db3")):
        check_sqlite(db)


def check_sqlite(path: Path, deadline_s: float = SQLITE_DEADLINE_S) -> None:
    """A rosbag2 .db3 from a user: opened read-only with untrusted schema, a deadline on every
    statement; views, triggers and virtual tables refused."""
    uri = f"file:{quote(str(path.resolve()))}?mode=ro&immutable=1"
    deadline = time.monotonic() + deadline_s
    try:
        conn = sqlite3.connect(uri, uri=True)
    except sqlite3.Error:
        raise InputError("not a readable ROS bag (no SQLite database)", path=path.name) from None
    try:
        conn.set_progress_handler(lambda: int(time.monotonic() > deadline), SQLITE_STEPS)
        conn.execute("PRAGMA trusted_schema = OFF")
        rows = conn.execute("SELECT type, name, sql FROM sqlite_master").fetchall()
    except sqlite3.Error as exc:
        reason = "took too long" if time.monotonic() > deadline else str(exc)[:120]
        raise InputError(f"not a readable ROS bag (SQLite: {reason})", path=path.name) from None
    finally:
        conn.close()
    for kind, name, sql in rows:
        if kind in ("view", "trigger") or (sql or "").lstrip().upper().startswith("CREATE VIRT"):
            raise InputError(
                f"the database holds a {kind if kind != 'table' else 'virtual table'} "
                f"{str(name)[:60]!r}: a rosbag2 database holds plain tables only",
                path=path.name,
            )


def read_upload_estimate(path: Path, topic: str | None, max_unpacked: int) -> Trajectory:
    """The estimate in an uploaded file (a .zip: a rosbag2 directory) with the checks above."""
    from worker.export.estimate import read_estimate

    if path.suffix.lower() == ".zip":
        path = unzip_rosbag2(path, path.parent, max_unpacked)
    if path.is_dir():
        check_rosbag2(path)
    elif path.suffix == ".db3":
        check_sqlite(path)
    return read_estimate(path, "auto", topic)
