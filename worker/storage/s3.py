"""The S3 backend (AWS S3, MinIO, Ceph RGW, ...) on boto3, configured the standard way:
AWS_ENDPOINT_URL (unset: AWS itself), AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY, AWS_REGION,
or any other source botocore reads (profiles, instance roles)."""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache
from pathlib import Path
from typing import Any, BinaryIO

from worker.storage.interface import CHUNK, Storage, StorageError, join

UPLOAD_THREADS = 8  # files of a report sent at once (most are small: latency, not bandwidth)
_LOCK = threading.Lock()


@lru_cache(maxsize=4)
def _client(endpoint: str | None, region: str | None) -> Any:
    """One boto3 client per endpoint (clients are thread-safe; making one costs ~50 ms)."""
    import boto3
    from botocore.config import Config

    # an endpoint of our own (MinIO, moto, Ceph) is addressed by path: its host name has no
    # wildcard DNS for bucket.host; AWS itself picks the style it prefers
    style = "path" if endpoint else "auto"
    config = Config(
        s3={"addressing_style": style}, connect_timeout=3, read_timeout=60,
        retries={"max_attempts": 4, "mode": "standard"}, max_pool_connections=UPLOAD_THREADS * 2,
    )  # fmt: skip
    with _LOCK:  # boto3's default session is not safe to use from two threads at once
        return boto3.session.Session().client(
            "s3", endpoint_url=endpoint, region_name=region or "us-east-1", config=config
        )


def _why(exc: Exception) -> str:
    """One line: what the S3 call ran into."""
    err = getattr(exc, "response", {}).get("Error", {}) if hasattr(exc, "response") else {}
    if err:
        return f"{err.get('Code', '?')}: {err.get('Message', '')}".rstrip(": ")
    return f"{type(exc).__name__}: {exc}".splitlines()[0]


def _missing(exc: Exception) -> bool:
    err = getattr(exc, "response", {}).get("Error", {}) if hasattr(exc, "response") else {}
    return str(err.get("Code")) in ("NoSuchKey", "404", "NotFound")


class S3Storage(Storage):
    """Keys under `prefix` in `bucket`."""

    def __init__(self, bucket: str, prefix: str = ""):
        self.bucket, self.prefix = bucket, prefix.strip("/")
        self.url = f"s3://{bucket}/{self.prefix}".rstrip("/")
        endpoint = os.environ.get("AWS_ENDPOINT_URL_S3") or os.environ.get("AWS_ENDPOINT_URL")
        region = os.environ.get("AWS_REGION") or os.environ.get("AWS_DEFAULT_REGION")
        try:
            self.s3 = _client(endpoint or None, region)
        except Exception as exc:  # no boto3, a malformed endpoint URL
            raise StorageError(f"S3 storage {self.url}: {_why(exc)}") from None

    @classmethod
    def from_url(cls, url: str) -> S3Storage:
        """The storage of an s3://bucket[/prefix] URL."""
        bucket, _, prefix = url.removeprefix("s3://").partition("/")
        return cls(bucket, prefix)

    def _key(self, key: str) -> str:
        if any(p in ("..", ".") for p in key.split("/")):
            raise StorageError(f"key {key!r} leaves its folder")
        return join(self.prefix, key)

    def _call(self, what: str, fn: Any, **kw: Any) -> Any:
        try:
            return fn(Bucket=self.bucket, **kw)
        except Exception as exc:
            if _missing(exc):
                raise FileNotFoundError(f"{self.url}: no {kw.get('Key', what)}") from None
            raise StorageError(f"S3 storage {self.url}: {what}: {_why(exc)}") from None

    def location(self, key: str) -> str:
        return f"s3://{self.bucket}/{self._key(key)}"

    def put_file(self, key: str, path: Path) -> None:
        try:  # multipart above 8 MB, in parallel parts; a part lost is retried, a key is whole
            self.s3.upload_file(str(path), self.bucket, self._key(key))
        except Exception as exc:
            raise StorageError(f"S3 storage {self.url}: upload of {key}: {_why(exc)}") from None

    def put_bytes(self, key: str, data: bytes) -> None:
        self._call("put", self.s3.put_object, Key=self._key(key), Body=data)

    def put_tree(self, prefix: str, folder: Path) -> list[str]:
        files = sorted(p for p in folder.rglob("*") if p.is_file())
        keys = [join(prefix, p.relative_to(folder).as_posix()) for p in files]
        with ThreadPoolExecutor(UPLOAD_THREADS) as pool:
            list(pool.map(self.put_file, keys, files))
        return keys

    def open(self, key: str) -> BinaryIO:
        body = self._call("get", self.s3.get_object, Key=self._key(key))["Body"]
        return _Body(body)

    def size(self, key: str) -> int | None:
        try:
            return int(self._call("head", self.s3.head_object, Key=self._key(key))["ContentLength"])
        except FileNotFoundError:
            return None

    def list(self, prefix: str) -> list[str]:
        base = self._key(prefix) + "/" if self._key(prefix) else ""
        keys: list[str] = []
        try:
            pages = self.s3.get_paginator("list_objects_v2").paginate(
                Bucket=self.bucket, Prefix=base
            )
            for page in pages:
                keys += [o["Key"][len(base) :] for o in page.get("Contents", [])]
        except Exception as exc:
            raise StorageError(f"S3 storage {self.url}: list {prefix}: {_why(exc)}") from None
        return sorted(keys)

    def delete_prefix(self, prefix: str) -> None:
        if not self._key(prefix) or not prefix.strip("/"):
            raise StorageError("refusing to delete the whole storage")
        keys = self.list(prefix)
        for i in range(0, len(keys), 1000):  # DeleteObjects takes 1000 keys at a time
            objs = [{"Key": self._key(join(prefix, k))} for k in keys[i : i + 1000]]
            self._call("delete", self.s3.delete_objects, Delete={"Objects": objs, "Quiet": True})

    def check(self) -> None:
        try:
            self._call("head bucket", self.s3.head_bucket)
        except FileNotFoundError:
            raise StorageError(f"S3 storage {self.url}: no bucket {self.bucket!r}") from None


class _Body:
    """botocore's StreamingBody as a closable binary stream read in CHUNK-sized pieces."""

    def __init__(self, body: Any):
        self.body = body

    def read(self, n: int = -1) -> bytes:
        try:
            return self.body.read(None if n < 0 else n)
        except Exception as exc:
            raise StorageError(f"S3 read broke off: {_why(exc)}") from None

    def readinto(self, buf: Any) -> int:
        data = self.read(min(len(buf), CHUNK))
        buf[: len(data)] = data
        return len(data)

    def close(self) -> None:
        self.body.close()

    def __enter__(self) -> _Body:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
