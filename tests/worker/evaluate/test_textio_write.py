"""Rows written chunk by chunk (`write_rows`): the bytes of the whole text written at once,
without the whole text in memory."""

from __future__ import annotations

import gzip
import tracemalloc

import numpy as np
import pytest

from worker.evaluate.relations import Relations
from worker.evaluate.textio import write_rows
from worker.evaluate.trajio import read_relations, write_relations

FMT = "%.6f %.6f %.9f\n"


def _columns(n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [np.sort(rng.uniform(0, 7200, n)), rng.uniform(0, 7200, n), rng.normal(0, 3, n)]


def _row_by_row(head: str, cols: list[np.ndarray]) -> str:
    # the plain definition: one printf per row, from Python floats
    return head + "".join(FMT % row for row in zip(*(c.tolist() for c in cols), strict=True))


@pytest.mark.parametrize("n, chunk", [(0, 7), (1, 7), (7, 7), (1000, 7), (1000, 100_000)])
def test_rows_are_the_text_of_a_printf_per_row(tmp_path, n, chunk):
    cols = _columns(n)
    path = tmp_path / "rows.txt"
    write_rows(path, FMT, cols, head="# t1 t2 e\n", chunk=chunk)
    assert path.read_bytes() == _row_by_row("# t1 t2 e\n", cols).encode()


def test_a_gz_name_gives_the_bytes_of_a_one_shot_gzip(tmp_path):
    cols = _columns(300_000, seed=1)  # 15 chunks of deflate input, 12 MB of text
    path = tmp_path / "rows.txt.gz"
    write_rows(path, FMT, cols, head="# head\n")
    text = _row_by_row("# head\n", cols).encode()
    assert gzip.decompress(path.read_bytes()) == text
    assert path.read_bytes() == gzip.compress(text, compresslevel=6, mtime=0)


def test_a_large_relations_file_is_written_without_its_text_in_memory(tmp_path):
    n = 1_000_000
    t1, t2, _ = _columns(n, seed=2)
    rel = Relations(t1, t2, np.random.default_rng(3).normal(0, 1, (n, 3)))
    path = tmp_path / "relations_SM.txt"
    tracemalloc.start()
    try:
        write_relations(path, rel)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    size = path.stat().st_size
    assert size > 60_000_000
    # the whole text and its bytes would be twice the file; a chunk of 20,000 rows of 73
    # bytes holds about 9 MB (its Python floats, text and bytes)
    assert peak < 0.2 * size
    back = read_relations(path)
    assert np.array_equal(back.t1, np.round(t1, 6))
    assert len(back.t2) == n
