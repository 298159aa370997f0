"""Parse the parts of a Stage `.world` file that describe the map and the robot's pose."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from worker.errors import InputError

# Tokens of Stage's world-file syntax: strings, brackets, parentheses, bare words/numbers.
_TOKEN = re.compile(r'"([^"]*)"|([()\[\]])|([^\s()\[\]"]+)')
# Entity types that are never the robot (they carry a `pose` too).
_NOT_ROBOT = {"window", "floorplan", "map", "zone", "include", "define", "model"}
# Blocks nested deeper than this are refused: Stage's own worlds nest a handful deep (a model
# inside a robot inside a define), and the recursive descent below must not meet Python's
# recursion limit on a hostile file (a 500 instead of a 400).
MAX_NESTING = 32


@dataclass(frozen=True)
class StageEntity:
    """One `type( key value ... )` block: its line, properties and nested blocks."""

    kind: str
    line: int
    props: dict
    children: tuple[StageEntity, ...]


@dataclass(frozen=True)
class StageMap:
    """What mapqual needs from a `.world` file."""

    bitmap: Path  # the image, joined to the file's folder (unchecked: see bitmap_ref)
    size: tuple[float, float]  # [m] width, height of the bitmap in the world
    center: tuple[float, float]  # [m] where the bitmap's centre sits in the world
    quarter_turns: int  # the bitmap's rotation in the world, counter-clockwise, 0..3 x 90 deg
    robot_pose: tuple[float, float, float] | None  # [m, m, rad] if a robot is placed
    bitmap_ref: str = ""  # the `bitmap` value as written (checked by worker.world.refs)


def _tokens(text: str) -> list[tuple[str, str, int]]:
    """`(kind, value, line)` tokens; kind is 'str', 'sym' or 'word'. Comments (#) dropped."""
    out = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        for m in _TOKEN.finditer(_strip_comment(raw)):
            if m.group(1) is not None:
                out.append(("str", m.group(1), lineno))
            elif m.group(2) is not None:
                out.append(("sym", m.group(2), lineno))
            else:
                out.append(("word", m.group(3), lineno))
    return out


def _strip_comment(raw: str) -> str:
    """Drop a `#` comment that is not inside a quoted string."""
    in_str = False
    for i, ch in enumerate(raw):
        if ch == '"':
            in_str = not in_str
        elif ch == "#" and not in_str:
            return raw[:i]
    return raw


def parse_entities(text: str, path: Path) -> list[StageEntity]:
    """Top-level entity blocks of a world file (`define` blocks are skipped)."""
    return _Parser(_tokens(text), path).entities()


class _Parser:
    """Recursive descent over the tokens of one world file; `pos` is the next token."""

    def __init__(self, toks: list, path: Path):
        self.toks = toks
        self.path = path
        self.pos = 0

    def _opens(self, sym: str) -> bool:
        return self.pos < len(self.toks) and self.toks[self.pos][:2] == ("sym", sym)

    def entities(self) -> list[StageEntity]:
        toks, path = self.toks, self.path
        entities = []
        while self.pos < len(toks):
            k, v, ln = toks[self.pos]
            self.pos += 1
            if k != "word":
                raise InputError(f"unexpected {v!r}", path=path, line=ln)
            if v == "define":
                # `define name parent ( ... )`: a type definition, not an instance; skip it.
                self.pos += 2
                if not self._opens("("):
                    raise InputError("malformed define", path=path, line=ln)
                self.pos += 1
                self.block("define", ln, 1)
            elif self._opens("("):
                self.pos += 1
                entities.append(self.block(v, ln, 1))
            else:
                self.value(ln)  # a global setting such as `resolution 0.02`
        return entities

    def block(self, kind: str, line: int, depth: int) -> StageEntity:
        toks, path = self.toks, self.path
        if depth > MAX_NESTING:
            raise InputError(
                f"blocks nested more than {MAX_NESTING} deep (a Stage world needs a few)",
                path=path, line=line,
            )  # fmt: skip
        props: dict = {}
        children = []
        while self.pos < len(toks):
            k, v, ln = toks[self.pos]
            if k == "sym" and v == ")":
                self.pos += 1
                return StageEntity(kind, line, props, tuple(children))
            if k != "word":
                raise InputError(f"unexpected {v!r}", path=path, line=ln)
            self.pos += 1
            if self._opens("("):
                self.pos += 1
                children.append(self.block(v, ln, depth + 1))
            else:
                props[v] = self.value(ln)
        raise InputError(f"block {kind!r} is never closed", path=path, line=line)

    def value(self, line: int):
        toks, path = self.toks, self.path
        if self.pos >= len(toks):
            raise InputError("missing value at end of file", path=path, line=line)
        k, v, ln = toks[self.pos]
        self.pos += 1
        if k == "sym" and v == "[":
            items = []
            while self.pos < len(toks) and toks[self.pos][:2] != ("sym", "]"):
                items.append(toks[self.pos][1])
                self.pos += 1
            if self.pos >= len(toks):
                raise InputError("'[' is never closed", path=path, line=ln)
            self.pos += 1
            return items
        if k == "sym":
            raise InputError(f"unexpected {v!r}", path=path, line=ln)
        return v


def _floats(values, n_min: int, what: str, path: Path, line: int) -> list[float]:
    """Parse a `[a b c]` list of at least n_min numbers."""
    if not isinstance(values, list) or len(values) < n_min:
        raise InputError(f"{what} needs at least {n_min} numbers", path=path, line=line)
    try:
        return [float(v) for v in values]
    except ValueError:
        raise InputError(f"{what} must be numbers, got {values}", path=path, line=line) from None


def read_stage_world(path: Path) -> StageMap:
    """The bitmap, its size and placement, and the robot's pose from a Stage `.world` file."""
    import math

    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=path) from None
    entities = parse_entities(text, path)
    maps = [e for e in entities if "bitmap" in e.props]
    if not maps:
        raise InputError("no floorplan/model block with a `bitmap` in this .world file", path=path)
    floor = maps[0]
    if "size" not in floor.props:
        raise InputError("the bitmap's block has no `size [w h z]`", path=path, line=floor.line)
    size = _floats(floor.props["size"], 2, "size", path, floor.line)
    if size[0] <= 0 or size[1] <= 0:
        raise InputError(f"size must be positive, got {size[:2]}", path=path, line=floor.line)
    center = (0.0, 0.0)
    yaw_deg = 0.0
    if "pose" in floor.props:
        p = _floats(floor.props["pose"], 2, "pose", path, floor.line)
        center = (p[0], p[1])
        yaw_deg = p[3] if len(p) >= 4 else (p[2] if len(p) == 3 else 0.0)
    quarter_turns = round(yaw_deg / 90.0)
    if abs(yaw_deg - 90.0 * quarter_turns) > 1e-6:
        raise InputError(
            f"the bitmap is rotated by {yaw_deg:g} degrees; only multiples of 90 are supported",
            path=path,
            line=floor.line,
        )
    robot_pose = None
    for ent in entities:
        if ent is floor or ent.kind in _NOT_ROBOT or "pose" not in ent.props:
            continue
        p = _floats(ent.props["pose"], 3, "pose", path, ent.line)
        # Stage 4 writes [x y z a], Stage 3 [x y a]; the angle is in degrees.
        yaw_deg = p[3] if len(p) >= 4 else p[2]
        robot_pose = (p[0], p[1], math.radians(yaw_deg))
        break
    bitmap = str(floor.props["bitmap"])
    return StageMap(
        bitmap=(path.parent / bitmap),
        size=(size[0], size[1]),
        center=center,
        quarter_turns=quarter_turns % 4,
        robot_pose=robot_pose,
        bitmap_ref=bitmap,
    )
