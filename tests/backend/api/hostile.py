"""A corpus of hostile uploads, each built here from a few bytes of code (nothing stored): bag
chunks, zip members and gzip streams that unpack to far more than they say, a rosbag2 that
asks the reader to unpack files to disk, SQLite that never ends, a Stage world nested past any
stack, a YAML pointing at the server's folder."""

from __future__ import annotations

import gzip
import io
import sqlite3
import struct
import tempfile
import zipfile
import zlib
from pathlib import Path

MB = 1 << 20


def _rosbag2(folder: Path, mode: str, storage: str, mb: int) -> Path:
    """A rosbag2 of `mb` MiB of zeros on a PoseStamped topic (what an estimate is read from;
    the reader decompresses before it deserializes), compressed as asked."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    w = Writer(folder / "bag", version=9, storage_plugin=plugin)
    if mode != "none":
        w.set_compression(CompressionMode[mode.upper()], CompressionFormat.ZSTD)
    w.open()
    conn = w.add_connection("/pose", "geometry_msgs/msg/PoseStamped", typestore=ts)
    w.write(conn, 1000, bytes(mb * MB))  # one message: one chunk
    w.close()
    return folder / "bag"


def mcap_zstd_bomb() -> bytes:
    """A bare .mcap (about 10 kB) whose one zstd chunk unpacks to 160 MiB."""
    with tempfile.TemporaryDirectory() as tmp:
        bag = _rosbag2(Path(tmp), "storage", "mcap", 160)
        return next(bag.glob("*.mcap")).read_bytes()


def rosbag1_bz2_bomb() -> bytes:
    """A rosbag1 (bz2 chunks) of 160 MiB of zeros in a few kB."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bomb.bag"
        w = Writer(path)
        w.set_compression(Writer.CompressionFormat.BZ2)
        w.chunk_threshold = 256 * MB  # one chunk
        w.open()
        conn = w.add_connection("/pose", "geometry_msgs/msg/PoseStamped", typestore=ts)
        data = bytes(8 * MB)
        for i in range(20):
            w.write(conn, i * 1000, data)
        w.close()
        return path.read_bytes()


def _zip(members: dict[str, tuple[bytes, int]]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, (data, method) in members.items():
            zf.writestr(zipfile.ZipInfo(name), data, compress_type=method)
    return buf.getvalue()


def zip_bzip2_declared_16() -> bytes:
    """A zip whose bzip2 member holds 64 MiB of zeros and whose index says 16 bytes."""
    meta = b"rosbag2_bagfile_information:\n  version: 9\n"
    raw = bytearray(_zip({"b/metadata.yaml": (meta, 0), "b/b.mcap": (b"\0" * 64 * MB, 12)}))
    for sig, offset in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):
        start = 0
        while (at := raw.find(sig, start)) >= 0:
            name_len = struct.unpack_from("<H", raw, at + (26 if sig == b"PK\x03\x04" else 28))[0]
            name_at = at + (30 if sig == b"PK\x03\x04" else 46)
            if raw[name_at : name_at + name_len] == b"b/b.mcap":
                struct.pack_into("<I", raw, at + offset, 16)
            start = at + 4
    return bytes(raw)


def zip_deflate_bomb() -> bytes:
    """A zip of a rosbag2 whose deflated storage file unpacks to 200 MiB (honestly declared)."""
    meta = b"rosbag2_bagfile_information:\n  version: 9\n"
    big = b"\0" * 200 * MB
    return _zip({"b/metadata.yaml": (meta, 8), "b/b.mcap": (big, zipfile.ZIP_DEFLATED)})


def zip_rosbag2_file_compression() -> bytes:
    """A zipped rosbag2 with compression_mode file: a 160 MiB .mcap.zstd to unpack to disk."""
    with tempfile.TemporaryDirectory() as tmp:
        bag = _rosbag2(Path(tmp), "file", "mcap", 160)
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
            for f in sorted(bag.iterdir()):
                zf.write(f, f"bag/{f.name}")
        return buf.getvalue()


def db3_recursive_view() -> bytes:
    """A rosbag2 .db3 whose `schema` is a recursive VIEW that never ends."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "x.db3"
        con = sqlite3.connect(path)
        con.executescript(
            "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT, "
            "serialization_format TEXT, offered_qos_profiles TEXT);"
            "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER, "
            "timestamp INTEGER, data BLOB);"
            "CREATE VIEW schema AS WITH RECURSIVE c(x) AS (SELECT 1 UNION ALL "
            "SELECT x + 1 FROM c) SELECT x AS schema_version, 'humble' AS ros_distro FROM c;"
        )
        con.close()
        return path.read_bytes()


def tum_gzip_bomb() -> bytes:
    """A TUM trajectory, gzipped: 300 MiB of a repeated line in about 300 kB."""
    line = b"0.0 0 0 0 0 0 0 1\n"
    return gzip.compress(line * (300 * MB // len(line)), compresslevel=1)


def stage_nested() -> bytes:
    """An 800 kB Stage world of blocks nested 160,000 deep."""
    return b'floorplan ( bitmap "a.png" size [1 1 1]\n' + b"b ( " * 160_000 + b")" * 160_001


def yaml_image_dot() -> bytes:
    """A map_server YAML whose image is the upload's folder itself."""
    return b"image: .\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"


def png_bytes(w: int = 80, h: int = 60) -> bytes:
    """A walled box as a PNG (an ordinary floorplan)."""
    rows = []
    for y in range(h):
        wall = y in (0, h - 1)
        rows.append(b"\0" + bytes(0 if wall or x in (0, w - 1) else 255 for x in range(w)))

    def chunk(tag: bytes, data: bytes) -> bytes:
        body = tag + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"".join(rows)))
        + chunk(b"IEND", b"")
    )
