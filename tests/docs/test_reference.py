"""The generated reference holds every CLI command and option, every API route, every
summary.json field, every parameter and every service setting, each found here from the code
by a walk of its own (not the generator's)."""

from __future__ import annotations

import dataclasses
import html
import re
import typing
from pathlib import Path

import pytest
import typer.main
from fastapi.routing import APIRoute

from mapqual.reference import GENERATORS, pages

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def generated() -> dict[str, str]:
    return pages()


def _section(page: str, heading: str) -> str:
    """The text of `page` from the heading line holding `heading` to the next heading."""
    lines = page.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("#") and heading in ln)
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("#")), len(lines))
    return "\n".join(lines[start:end])


def _cli_commands():
    out = []
    stack = [("mapqual", typer.main.get_command(__import__("mapqual.cli").cli.app))]
    while stack:
        name, cmd = stack.pop()
        out.append((name, cmd))
        stack += [(f"{name} {n}", c) for n, c in getattr(cmd, "commands", {}).items()]
    return out


def test_every_cli_command_and_option_is_in_the_reference(generated):
    page = generated["reference/cli.md"]
    commands = _cli_commands()
    assert len(commands) >= 25  # 18 top-level commands and the groups' subcommands
    for name, cmd in commands:
        section = _section(page, f"`{name}`")
        for param in cmd.params:
            if param.param_type_name == "option":
                for opt in [*param.opts, *param.secondary_opts]:
                    assert re.search(rf"(?<![\w-]){re.escape(opt)}(?![\w-])", section), (
                        f"{name}: {opt} is missing from the reference"
                    )
            else:
                # an argument is shown with its help text (or its name when it has none)
                shown = html.escape((param.help or param.name).split(".")[0], quote=False)
                assert shown in section, (name, param.name)


def _api_routes(routes, prefix: str = "") -> list[tuple[str, APIRoute]]:
    """(full path, route) of every APIRoute of the app, inside included routers too."""
    out = []
    for r in routes:
        if isinstance(r, APIRoute):
            out.append((prefix + r.path, r))
        elif hasattr(r, "original_router"):  # FastAPI's record of an included router
            context = getattr(r, "include_context", None)
            inner = prefix + (context.prefix if context else "")
            out += _api_routes(r.original_router.routes, inner)
    return out


def test_every_api_route_is_in_the_reference(generated):
    from mapqual.app import app

    page = generated["reference/api.md"]
    routes = [(p, r) for p, r in _api_routes(app.routes) if r.include_in_schema]
    assert len(routes) >= 25
    assert any(p == "/api/v1/runs/{run_id}/bag" for p, _ in routes)
    for path, route in routes:
        path = re.sub(r"\{(\w+):\w+\}", r"{\1}", path)  # {name:path}: OpenAPI says {name}
        for method in route.methods - {"HEAD"}:
            assert f"`{method} {path}`" in page, f"{method} {path} is missing"


def _run_param_keys() -> list[str]:
    from worker.run_params import RunParams

    keys = []

    def walk(prefix: str, cls: type) -> None:
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            key = f"{prefix}{f.name}"
            keys.append(key)
            inner = [a for a in (hints[f.name], *typing.get_args(hints[f.name]))]
            inner = [a for a in inner if dataclasses.is_dataclass(a) and isinstance(a, type)]
            if inner:
                walk(f"{key}.", inner[0])

    walk("", RunParams)
    return keys


def test_every_run_parameter_is_in_the_reference_with_its_default(generated):
    from worker.run_params import RunParams

    page = generated["reference/parameters.md"]
    keys = _run_param_keys()
    assert {"sim.laser_noise_sigma", "slam.graph.link_gate_chi2", "eval.b.min_relations"} <= set(
        keys
    )
    rows = {m.group(1): m.group(0) for m in re.finditer(r"^\| `([\w.]+)` \|.*$", page, re.M)}
    defaults = RunParams()
    for key in keys:
        assert key in rows, f"parameter {key} is missing"
        value = defaults
        for part in key.split("."):
            value = getattr(value, part) if value is not None else None
        plain = isinstance(value, int | float | str) and not isinstance(value, bool)
        if plain and key != "explore.costmap.footprint_half_m":  # derived: shown as such
            shown = html.escape(repr(value), quote=False)
            assert f"<code>{shown}</code>" in rows[key], (key, value, rows[key])


def test_every_parameter_dataclass_of_the_code_is_in_the_reference(generated):
    page = generated["reference/parameters.md"]
    # found by a plain text search of the source, not the generator's AST walk
    found = set()
    for path in (ROOT / "worker").rglob("*.py"):
        text = path.read_text()
        found |= set(re.findall(r"@dataclass(?:\([^)]*\))?\nclass (\w+(?:Params|Spec))\b", text))
    assert {"SimParams", "MapScoreParams", "FeatureParams", "TrainParams", "LaserSpec"} <= found
    for name in found:
        assert re.search(rf"^###.*\b{name}\b", page, re.M), f"{name} has no section"


def test_the_units_and_meanings_come_from_the_field_comments(generated):
    page = generated["reference/parameters.md"]
    # hand-read from worker/sim/params.py and worker/slam/params.py
    assert re.search(r"\| `sim.dt` \| float \| <code>0.1</code> \| s \| public step;", page)
    assert re.search(
        r"\| `slam.angular_update` \| float \| <code>0.25</code> \| rad \| angularUpdate", page
    )
    settings = generated["reference/settings.md"]
    assert re.search(r"\| `MAPQUAL_QUOTA_WORLDS` \| `500` \|  \| Per-owner quotas", settings)


def test_every_summary_field_and_setting_is_in_the_reference(generated):
    from backend.core.config import Settings
    from worker.report.summary import RunSummary

    page = generated["reference/summary.md"]
    for name in RunSummary.model_fields:
        assert f"| `{name}` |" in page, name
    assert '"title": "RunSummary"' in page  # the JSON Schema itself
    settings = generated["reference/settings.md"]
    for info in Settings.model_fields.values():
        assert f"| `{info.alias}` |" in settings, info.alias


def test_the_nav_lists_every_generated_page():
    nav = (ROOT / "mkdocs.yml").read_text()
    for path in GENERATORS:
        assert f": {path}" in nav, path


@dataclasses.dataclass(frozen=True)
class _Sample:
    """A hand-made parameter class: each field's expected comment is written out below."""

    # --- a section header, no field's comment ---
    a: float = 1.0  # [m] trailing only
    # a block above
    # on two lines
    b: int = 2
    # shared by the run of fields below, none of which has its own
    c: int = 3
    d: int = 4

    e: str = "x"  # [rad/s] unit and meaning
    f: int = 5


def test_field_comments_by_a_hand_made_class():
    from mapqual.reference.comments import field_comments, prose, split_unit

    got = field_comments(_Sample)
    assert got == {
        "a": "[m] trailing only",
        "b": "a block above on two lines",
        "c": "shared by the run of fields below, none of which has its own",
        "d": "shared by the run of fields below, none of which has its own",
        "e": "[rad/s] unit and meaning",
        "f": "",
    }
    assert split_unit(got["e"]) == ("rad/s", "unit and meaning")
    assert split_unit("Stage E for x [-]") == ("-", "Stage E for x [-]")
    assert prose("runs/<id>/ and `a<b>`") == "runs/&lt;id&gt;/ and `a<b>`"
