"""Text I/O for numeric tables: bulk parsing (numba on bytes, else numpy), errors by line."""

from __future__ import annotations

import gzip
import io
import itertools
import warnings
import zlib
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from worker.decompress_budget import spend, step
from worker.errors import InputError, InputWarning

_GZIP_MAGIC = b"\x1f\x8b"


def read_bytes(path: str | Path) -> bytes:
    """The bytes of a file; gzip-compressed files (by their magic bytes) are inflated."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise InputError("no such file", path=p) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a file", path=p) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=p) from None
    if raw[:2] == _GZIP_MAGIC:
        raw = _inflate(raw, p)
    return raw


def _inflate(raw: bytes, path: Path) -> bytes:
    """gzip data (one or more members) inflated. A stream that ends early (a copy cut off)
    gives what it holds, with an InputWarning: the reader then finds a truncated last line.
    Inflated piece by piece, each counted against the process's decompression budget
    (`worker.decompress_budget`: unlimited unless the upload sandbox set one)."""
    out = []
    while raw:
        inflater = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
        data = raw
        try:
            while True:
                piece = inflater.decompress(data, step())
                spend(len(piece))
                out.append(piece)
                data = inflater.unconsumed_tail
                if inflater.eof or (not data and not piece):
                    break
        except zlib.error as exc:
            raise InputError(f"corrupt gzip data: {exc}", path=path) from None
        if not inflater.eof:
            warnings.warn(
                InputWarning(f"{path}: the gzip data ends early: reading what it holds"),
                stacklevel=3,
            )
            break
        raw = inflater.unused_data
        if raw[:2] != _GZIP_MAGIC:
            break  # trailing garbage after the last member, as gzip.decompress ignores zeros
    return b"".join(out)


def _decode(raw: bytes, path: Path) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"not a text file (byte {exc.start} is not UTF-8)", path=path) from None


def read_text(path: str | Path) -> str:
    """The text (UTF-8) of a file; gzip-compressed files are inflated."""
    return _decode(read_bytes(path), Path(path))


def _strip_comment(line: str) -> str:
    i = line.find("#")
    return (line if i < 0 else line[:i]).strip()


def _find_bad_line(
    lines: Sequence[str], linenos: Sequence[int] | None, ncols: int, what: str, path: str | Path
) -> InputError:
    """Slow path: the first line that is not `ncols` finite numbers, as an InputError."""
    for k, line in enumerate(lines):
        lineno = linenos[k] if linenos is not None else k + 1
        body = _strip_comment(line)
        if not body:
            continue
        tokens = body.split()
        if len(tokens) != ncols:
            return InputError(
                f"expected {ncols} numbers ({what}), got {len(tokens)}", path=path, line=lineno
            )
        for tok in tokens:
            try:
                v = float(tok)
            except ValueError:
                msg = f"not a number: {tok!r} (expected {what})"
                return InputError(msg, path=path, line=lineno)
            if not np.isfinite(v):
                return InputError(f"non-finite value {tok!r}", path=path, line=lineno)
    return InputError(f"could not parse as {ncols} columns ({what})", path=path)


def parse_table(text: str, ncols: int, what: str, path: str | Path) -> NDArray[np.float64]:
    """Rows of exactly `ncols` finite numbers, `(K, ncols)`; blank lines and `#` comments are
    skipped. numpy's C parser does the work; only when it fails is the text walked line by
    line, to name the first bad line (numpy's row numbers do not count skipped lines)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            table = np.loadtxt(io.StringIO(text), dtype=np.float64, comments="#", ndmin=2)
    except ValueError:
        raise _find_bad_line(text.splitlines(), None, ncols, what, path) from None
    if table.size == 0:
        return np.zeros((0, ncols))
    if table.shape[1] != ncols or not np.isfinite(table).all():
        raise _find_bad_line(text.splitlines(), None, ncols, what, path)
    return table


def is_row(line: str, ncols: int) -> bool:
    """True for a blank or comment line, or one of exactly ncols finite numbers."""
    tokens = _strip_comment(line).split()
    if not tokens:
        return True
    try:
        return len(tokens) == ncols and bool(np.isfinite([float(t) for t in tokens]).all())
    except ValueError:
        return False


def drop_truncated_tail(text: str, valid: Callable[[str], bool], path: str | Path) -> str:
    """The text without its last line when that line has no newline and is not `valid` (a
    file cut off while it was written), with an InputWarning naming the line; else as is.
    Any other bad line is the parser's to report."""
    if not text or text.endswith("\n"):
        return text
    cut = text.rfind("\n") + 1
    if valid(text[cut:]):
        return text
    lineno = text.count("\n", 0, cut) + 1
    warnings.warn(
        InputWarning(f"{path}:{lineno}: the last line is truncated: skipped"), stacklevel=3
    )
    return text[:cut]


def load_table(path: str | Path, ncols: int, what: str) -> NDArray[np.float64]:
    """`parse_table` of a file (`.gz` transparently). Plain decimal tables, what our writers
    emit, go through a numba byte parser (`parse_kernels`); anything else through numpy.
    A truncated last line is skipped with a warning (`drop_truncated_tail`)."""
    from worker.evaluate.parse_kernels import OK, parse_decimal_table

    p = Path(path)
    raw = read_bytes(p)
    table, status = parse_decimal_table(np.frombuffer(raw, dtype=np.uint8), ncols)
    if status == OK:
        return table
    text = drop_truncated_tail(_decode(raw, p), lambda line: is_row(line, ncols), p)
    return parse_table(text, ncols, what, p)


def parse_columns(lines: Sequence[str], usecols: Sequence[int]) -> NDArray[np.float64] | None:
    """The given columns of whitespace-separated lines, `(K, len(usecols))`, or None when
    numpy cannot parse them all (a short line, a non-number): the caller then goes line by
    line. Other columns may hold anything (CARMEN's trailing host name)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            return np.loadtxt(
                lines, dtype=np.float64, comments=None, usecols=list(usecols), ndmin=2
            )
    except (ValueError, IndexError):
        return None


def row_chunks(fmt: str, columns: Sequence[NDArray], chunk: int) -> Iterator[str]:
    """The text of rows formatted with the printf-style `fmt` (one row, newline included) from
    equally long 1-D columns, `chunk` rows at a time; one `%` per chunk, far faster than a
    loop per row."""
    n = len(columns[0]) if columns else 0
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        flat = np.column_stack([np.asarray(c[start:stop], dtype=np.float64) for c in columns])
        yield (fmt * (stop - start)) % tuple(flat.ravel().tolist())


def write_rows(
    path: str | Path, fmt: str, columns: Sequence[NDArray], *, head: str = "",
    chunk: int = 20_000,
) -> None:  # fmt: skip
    """`head`, then the rows of `columns` formatted with `fmt` (`row_chunks`), written chunk by
    chunk: the same bytes as the whole text written at once, without it in memory (the SM
    relations of a 7,200 s run are 480 MB of it, and its bytes as much again); a chunk of
    `chunk` rows holds about 470 bytes a row at once (its floats, text and bytes). A `.gz`
    name is gzip-compressed as write_text does it (level 6, no time stamp)."""
    p = Path(path)
    packer = zlib.compressobj(level=6, wbits=31) if p.suffix == ".gz" else None
    try:
        with p.open("wb") as f:
            for text in itertools.chain([head], row_chunks(fmt, columns, chunk)):
                data = text.encode("utf-8")
                f.write(data if packer is None else packer.compress(data))
            if packer is not None:
                f.write(packer.flush())
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror}", path=p) from None


def write_text(path: str | Path, text: str) -> None:
    """Write text; a `.gz` name is gzip-compressed."""
    p = Path(path)
    data = text.encode("utf-8")
    try:
        if p.suffix == ".gz":
            data = gzip.compress(data, compresslevel=6, mtime=0)
        p.write_bytes(data)
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror}", path=p) from None
