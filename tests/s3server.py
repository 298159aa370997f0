"""A real S3 HTTP endpoint for tests: moto's standalone server as a subprocess on a free
loopback port, reached by the product's own boto3 client through AWS_ENDPOINT_URL."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager, suppress

import pytest


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def s3_server() -> Iterator[dict[str, str]]:
    """The environment (AWS_*) that points boto3 at a fresh moto server, which is stopped
    afterwards; os.environ holds it meanwhile."""
    port = _free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    env = {
        "AWS_ENDPOINT_URL": f"http://127.0.0.1:{port}", "AWS_ACCESS_KEY_ID": "test",
        "AWS_SECRET_ACCESS_KEY": "test", "AWS_REGION": "us-east-1",
    }  # fmt: skip
    try:
        deadline = time.monotonic() + 20
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                break
            except OSError:
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise RuntimeError("moto's S3 server did not start") from None
                time.sleep(0.1)
        with pytest.MonkeyPatch.context() as mp:
            for k, v in env.items():
                mp.setenv(k, v)
            yield env
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def make_bucket(env: dict[str, str]) -> str:
    """A new bucket on the server of `env` (made with a client of its own)."""
    name = f"t{uuid.uuid4().hex[:12]}"
    raw_client(env).create_bucket(Bucket=name)
    return name


def raw_client(env: dict[str, str]):
    """A boto3 client of the test's own (not the product's cached one) to check objects."""
    import boto3

    return boto3.client(
        "s3", endpoint_url=env["AWS_ENDPOINT_URL"], region_name="us-east-1",
        aws_access_key_id="test", aws_secret_access_key="test",
    )  # fmt: skip


@contextmanager
def slow_proxy(target_port: int, bytes_per_s: int) -> Iterator[int]:
    """A TCP proxy on a free loopback port to `target_port` that passes what clients send at
    `bytes_per_s` per connection (responses at full speed): uploads through it take seconds,
    long enough to kill an uploader midway. Yields its port."""
    import threading

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(64)
    stop = threading.Event()

    def pump(src: socket.socket, dst: socket.socket, rate: int | None) -> None:
        try:
            while not stop.is_set() and (data := src.recv(4096)):
                dst.sendall(data)
                if rate:
                    time.sleep(len(data) / rate)
        except OSError:
            pass
        finally:
            for s in (src, dst):
                with suppress(OSError):
                    s.shutdown(socket.SHUT_RDWR)

    def accept() -> None:
        while not stop.is_set():
            try:
                client, _ = listener.accept()
            except OSError:
                return
            upstream = socket.create_connection(("127.0.0.1", target_port))
            for a, b, rate in ((client, upstream, bytes_per_s), (upstream, client, None)):
                threading.Thread(target=pump, args=(a, b, rate), daemon=True).start()

    threading.Thread(target=accept, daemon=True).start()
    try:
        yield listener.getsockname()[1]
    finally:
        stop.set()
        listener.close()


__all__ = ["make_bucket", "raw_client", "s3_server", "slow_proxy"]
