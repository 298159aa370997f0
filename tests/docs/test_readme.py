"""The README is a front door: short, its two commands exactly what CI runs, its links alive,
and no lab notebook (commit hashes and time stamps live in the manual's results)."""

from __future__ import annotations

import re

from tests.docs.conftest import ROOT

README = (ROOT / "README.md").read_text()
MAIN = (
    "python3 -m venv .venv && .venv/bin/pip install -q -e . && "
    ".venv/bin/mapqual run worlds/bormann/office_a.yaml"
)
TESTS = (
    "python3 -m venv .venv && .venv/bin/pip install -q -e '.[dev]' && .venv/bin/python -m pytest -q"
)


def test_the_readme_is_under_300_lines():
    assert len(README.splitlines()) < 300


def test_the_two_commands_are_there_and_ci_runs_the_test_command():
    assert f"```sh\n{MAIN}\n```" in README
    assert f"```sh\n{TESTS}\n```" in README
    ci = (ROOT / ".ci/run").read_text().splitlines()
    assert TESTS in ci, "`.ci/run` must run exactly the README's test command"


def test_every_relative_link_of_the_readme_exists():
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README)
    local = [link for link in links if "://" not in link]
    assert len(local) >= 8
    for link in local:
        assert (ROOT / link).exists(), f"README links to {link}, which does not exist"


def test_the_readme_keeps_no_history():
    assert not re.search(r"\b[0-9a-f]{7,40}\b", README), "a commit hash in the README"
    assert not re.search(r"\b\d\d:\d\d(-\d\d:\d\d)? UTC\b|\b20\d\d-\d\d-\d\d\b", README)
    assert "/api/v1/docs" in README and "/api/v1/openapi.json" in README
    assert "`/docs`" not in README
