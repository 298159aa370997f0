"""A class's field comments, read from its source: the unit and meaning the code gives them.

The parameter classes document each field by a trailing comment (`x: float = 0.1  # [s] ...`)
and, for longer reasons, by a block of comment lines directly above it; this reads both.
"""

from __future__ import annotations

import ast
import html
import inspect
import io
import re
import textwrap
import tokenize
from functools import cache

# a unit in brackets, as the code writes them: [m], [rad/s], [-], [1/m], [m/m]
_UNIT = re.compile(r"\[([^\]\s][^\]]{0,14})\]")


@cache
def field_comments(cls: type) -> dict[str, str]:
    """Field name -> its comment text (block above, then the trailing one), for class `cls`."""
    try:
        source = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):
        return {}
    comments = _comments_by_line(source)
    lines = source.splitlines()
    (node,) = ast.parse(source).body
    assert isinstance(node, ast.ClassDef)
    # (name, block above, trailing comment, directly below the previous field)
    rows: list[tuple[str, str, str, bool]] = []
    last_end = -1
    for stmt in node.body:
        if not (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)):
            last_end = -1
            continue
        above = _block_above(lines, comments, stmt.lineno)
        end = stmt.end_lineno or stmt.lineno
        own = lines[end - 1].strip().startswith("#")
        trailing = "" if own else comments.get(end, "")
        rows.append((stmt.target.id, above, trailing, stmt.lineno == last_end + 1))
        last_end = end
    return _resolve(rows)


def _block_above(lines: list[str], comments: dict[int, str], lineno: int) -> str:
    """The comment lines directly above line `lineno` (1-based), up to a section header."""
    above: list[str] = []
    line = lineno - 1
    while line >= 1 and lines[line - 1].strip().startswith("#"):
        text = comments.get(line, "")
        if text.startswith("---"):  # a section header, not this field's comment
            break
        above.insert(0, text)
        line -= 1
    return " ".join(above)


def _resolve(rows: list[tuple[str, str, str, bool]]) -> dict[str, str]:
    """Each field's comment. A block above a run of fields none of which has a comment of its
    own (up to a blank line) speaks for all of them, as `# quotas: ...` above four settings."""
    out: dict[str, str] = {}
    for i, (name, above, trailing, _) in enumerate(rows):
        out.setdefault(name, " ".join(p for p in (above, trailing) if p))
        if not above or trailing:
            continue
        run = []
        for later, l_above, l_trailing, joined in rows[i + 1 :]:
            if not joined:
                break
            if l_above or l_trailing:
                run = []
                break
            run.append(later)
        for later in run:
            out[later] = above
    return out


def _comments_by_line(source: str) -> dict[int, str]:
    """1-based line -> the text of the comment on it, without `#`."""
    out: dict[int, str] = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            out[tok.start[0]] = tok.string.lstrip("#").strip()
    return out


def split_unit(comment: str) -> tuple[str, str]:
    """(unit, meaning): the first bracketed unit of a comment, and the comment without it
    when the unit opens it."""
    match = _UNIT.search(comment)
    if match is None:
        return "", comment
    unit = match.group(1)
    if match.start() == 0:
        comment = comment[match.end() :].strip()
    return unit, comment


def prose(text: object) -> str:
    """Text from the code as Markdown: `<id>` outside backquotes is text, not an HTML tag."""
    parts = re.split(r"(`[^`]*`)", str(text))
    return "".join(p if p.startswith("`") else html.escape(p, quote=False) for p in parts)


def cell(text: object) -> str:
    """Text fit for one Markdown table cell."""
    return prose(text).replace("|", "\\|").replace("\n", " ").strip()


def code_cell(text: object) -> str:
    """Text as code in one Markdown table cell: an HTML code element, its pipes as entities
    (a backslash-escaped pipe inside backquotes would show its backslash)."""
    return f"<code>{html.escape(str(text), quote=False).replace('|', '&#124;')}</code>"
