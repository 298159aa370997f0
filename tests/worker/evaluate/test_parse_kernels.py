"""The numba decimal-table parser equals Python's float() bit for bit, or gives up."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from worker.evaluate.parse_kernels import GIVE_UP, OK, parse_decimal_table
from worker.evaluate.relations import Relations
from worker.evaluate.trajio import write_relations


def parse(text: str, ncols: int):
    return parse_decimal_table(np.frombuffer(text.encode(), dtype=np.uint8), ncols)


finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
fmt = st.sampled_from(["%.6f", "%.9f", "%.3e", "%g", "%.12g", "%r", "%.0f", "%E"])


def surely_fast(token: str) -> bool:
    """Well inside the exact range: < 9e14 as an integer mantissa, power of ten <= 22."""
    mant, _, exp = token.lower().partition("e")
    frac = len(mant.split(".")[1]) if "." in mant else 0
    k = (int(exp) if exp else 0) - frac
    return int(mant.lstrip("+-").replace(".", "")) < 9 * 10**14 and -22 <= k <= 22


@given(st.lists(st.tuples(finite, fmt), min_size=1, max_size=40), st.integers(1, 4))
def test_accepted_numbers_equal_python_float(values, ncols):
    tokens = [(f % v) if f != "%r" else repr(v) for v, f in values]
    tokens = tokens[: len(tokens) // ncols * ncols] or tokens[:1] * ncols
    lines = [" ".join(tokens[i : i + ncols]) for i in range(0, len(tokens), ncols)]
    table, status = parse("\n".join(lines) + "\n", ncols)
    if all(surely_fast(t) for t in tokens):
        assert status == OK
    if status == OK:
        expect = np.array([float(t) for t in tokens]).reshape(-1, ncols)
        assert table.tobytes() == expect.tobytes()  # bit for bit, signs of zero included


def test_the_writers_files_always_take_the_fast_path(tmp_path, rng):
    m = 1000
    t1 = rng.uniform(0, 2e9, m)  # up to epoch-sized timestamps
    rel = Relations(t1, t1 + rng.uniform(0, 1e4, m), rng.uniform(-1e5, 1e5, (m, 3)))
    write_relations(tmp_path / "r.txt", rel)
    raw = (tmp_path / "r.txt").read_bytes()
    table, status = parse_decimal_table(np.frombuffer(raw, dtype=np.uint8), 8)
    assert status == OK and table.shape == (m, 8)
    expect = [[float(x) for x in line.split()] for line in raw.decode().splitlines()]
    assert table.tobytes() == np.array(expect).tobytes()


def test_comments_blank_lines_crlf_and_forms():
    text = "# header\r\n\r\n  1 -2.5 .5\t# trailing\r\n+3. 1e2 -0.0\n\n# end"
    table, status = parse(text, 3)
    assert status == OK
    np.testing.assert_array_equal(table, [[1.0, -2.5, 0.5], [3.0, 100.0, -0.0]])
    assert np.signbit(table[1, 2])
    empty, status = parse("# nothing\n\n", 3)
    assert status == OK and empty.shape == (0, 3)


@pytest.mark.parametrize(
    "text",
    [
        "1 2\n3\n",  # short line
        "1 2 3\n",  # long line
        "1 nan\n",
        "1 inf\n",
        "1 0x1p3\n",
        "1 1.2.3\n",
        "1 12abc\n",
        "1 -\n",
        "1 1e\n",
        "1 12345678901234567890\n",  # more digits than a double holds exactly
        "1 1e-30\n",  # beyond the exact powers of ten
    ],
)
def test_gives_up_on_anything_else(text):
    _, status = parse(text, 2)
    assert status == GIVE_UP
