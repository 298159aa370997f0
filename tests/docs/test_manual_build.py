"""The manual builds in strict mode; a broken link or a page missing from the nav fails it."""

from __future__ import annotations

import re

import yaml

from tests.docs.conftest import ROOT, build_manual


def _nav_pages(nav) -> list[str]:
    out = []
    for item in nav:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        out += _nav_pages(value) if isinstance(value, list) else [value]
    return out


def _config() -> dict:
    # mkdocs.yml holds no custom tags; a plain loader reads it
    return yaml.safe_load((ROOT / "mkdocs.yml").read_text())


def test_every_page_of_the_nav_is_built(built_site):
    pages = _nav_pages(_config()["nav"])
    assert len(pages) >= 30
    for page in pages:
        html = built_site / re.sub(r"(index)?\.md$", "", page) / "index.html"
        if page == "index.md":
            html = built_site / "index.html"
        assert html.is_file(), f"{page} was not built"
    # the generated reference is in the site, with its content
    cli = (built_site / "reference/cli/index.html").read_text()
    assert "mapqual run" in cli and "--time-limit" in cli
    api = (built_site / "reference/api/index.html").read_text()
    assert "/api/v1/runs/{run_id}/bag" in api
    # the pictures came along
    assert (built_site / "img/office_a_overlay.png").stat().st_size > 10_000


def test_the_config_is_strict():
    config = _config()
    assert config["strict"] is True
    assert config["validation"]["links"]["not_found"] == "warn"  # strict: a warning fails
    assert config["validation"]["nav"]["not_found"] == "warn"


def test_a_broken_link_or_a_missing_page_fails_the_build(tmp_path):
    # the manual's own settings (strict, validation, theme, extensions) on a two-page site, so
    # that this costs a second, not a second build of the whole manual with its reference
    config = {k: v for k, v in _config().items() if k not in ("hooks", "nav", "exclude_docs")}
    config["nav"] = [{"Home": "index.md"}, {"Page": "page.md"}, {"Gone": "gone.md"}]
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs/index.md").write_text("# Home\n\nSee [the page](page.md).\n")
    (tmp_path / "docs/page.md").write_text("# Page\n\nSee [the lost page](howto/lost.md).\n")
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(config))
    done = build_manual(tmp_path / "mkdocs.yml", tmp_path / "site")
    assert done.returncode != 0
    assert "howto/lost.md" in done.stderr and "gone.md" in done.stderr
    # and the same site without the two faults builds
    (tmp_path / "docs/page.md").write_text("# Page\n\nSee [home](index.md).\n")
    config["nav"] = config["nav"][:2]
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(config))
    assert build_manual(tmp_path / "mkdocs.yml", tmp_path / "site").returncode == 0
