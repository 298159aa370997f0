"""Both storage backends behave alike through the one interface: the local folder, and S3
over HTTP (moto's server) through the product's boto3 client."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from tests.s3server import make_bucket, raw_client, s3_server
from worker.storage import StorageError, check_setting, open_storage, run_files
from worker.storage.local import LocalStorage
from worker.storage.s3 import S3Storage


@pytest.fixture(scope="module")
def s3env():
    with s3_server() as env:
        yield env


@pytest.fixture(params=["local", "s3"])
def store(request, tmp_path, s3env):
    if request.param == "local":
        return LocalStorage(tmp_path / "store")
    return S3Storage(make_bucket(s3env), "pre/fix")


def test_put_list_read_delete_alike(store, tmp_path):
    src = tmp_path / "src"
    (src / "sub").mkdir(parents=True)
    (src / "a.txt").write_text("alpha")
    big = bytes(range(256)) * 50_000  # 12.8 MB: a multipart upload on S3
    (src / "sub" / "big.bin").write_bytes(big)
    assert store.put_tree("runs/1/x", src) == ["runs/1/x/a.txt", "runs/1/x/sub/big.bin"]
    assert store.list("runs/1/x") == ["a.txt", "sub/big.bin"]
    assert store.size("runs/1/x/sub/big.bin") == len(big)
    assert store.size("runs/1/x/none") is None
    got = b"".join(store.iter_bytes("runs/1/x/sub/big.bin", 1 << 16))
    assert hashlib.sha256(got).digest() == hashlib.sha256(big).digest()
    with pytest.raises(FileNotFoundError):
        store.open("runs/1/x/none")
    store.put_bytes("runs/1/y/b.txt", b"beta")
    store.delete_prefix("runs/1/x")
    assert store.list("runs/1") == ["y/b.txt"]
    with pytest.raises(StorageError):
        store.delete_prefix("")
    with pytest.raises(StorageError):
        store.open("runs/../../etc/passwd")


def test_a_location_opens_the_same_files_again(store):
    store.put_bytes("runs/7/att/summary.json", b"{}")
    files = run_files(store.location("runs/7/att"))
    assert files.names() == ["summary.json"]
    assert files.read_bytes("summary.json") == b"{}"
    files.check()


def test_s3_objects_are_where_the_location_says(s3env):
    bucket = make_bucket(s3env)
    store = S3Storage(bucket, "p")
    store.put_bytes("runs/3/a/f.txt", b"hello")
    assert store.location("runs/3/a") == f"s3://{bucket}/p/runs/3/a"
    body = raw_client(s3env).get_object(Bucket=bucket, Key="p/runs/3/a/f.txt")["Body"].read()
    assert body == b"hello"


def test_an_unreachable_bucket_says_why(s3env, monkeypatch):
    missing = S3Storage("no-such-bucket-here")
    with pytest.raises(StorageError, match="no-such-bucket-here"):
        missing.check()
    with pytest.raises(StorageError, match="does not exist"):
        run_files("s3://no-such-bucket-here/runs/1/a").check()


def test_a_missing_local_folder_is_unreachable_not_empty_success(tmp_path):
    with pytest.raises(StorageError, match="missing or empty"):
        run_files(str(tmp_path / "gone")).check()


def test_the_setting_is_checked(tmp_path):
    assert isinstance(open_storage("local", tmp_path), LocalStorage)
    assert isinstance(open_storage("s3://b/p", tmp_path), S3Storage)
    for bad in ("s3://", "ftp://x", "/data/runs"):
        with pytest.raises(ValueError, match="MAPQUAL_STORAGE"):
            check_setting(bad)


def test_local_keys_stay_inside(tmp_path):
    store = LocalStorage(tmp_path / "s")
    with pytest.raises(StorageError):
        store.put_bytes("../escape", b"x")
    assert not (tmp_path / "escape").exists()
    assert store.local_path("a/b") == Path(tmp_path / "s" / "a" / "b").resolve()
