"""report.html from its Jinja2 template: hand-checked cells, escaping, a well-formed page."""

from __future__ import annotations

from html.parser import HTMLParser
from importlib.resources import files

from tests.summaries import make_summary, relation, stats
from worker.batch.experiment import RunSpec
from worker.batch.html import write_html
from worker.batch.state import record_of

VOID = {"meta", "img", "br", "hr", "link", "input"}


class _Page(HTMLParser):
    """The rows of every table (cell texts, and the cells' classes and links), and whether
    every element is closed in order."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tables: list[list[list[str]]] = []
        self.classes: list[str | None] = []
        self.links: list[str] = []
        self.stack: list[str] = []
        self.balanced = True

    def handle_starttag(self, tag, attrs):
        if tag not in VOID:
            self.stack.append(tag)
        a = dict(attrs)
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self.tables[-1][-1].append("")
            self.classes.append(a.get("class"))
        elif tag == "a":
            self.links.append(a["href"])

    def handle_endtag(self, tag):
        self.balanced &= bool(self.stack) and self.stack.pop() == tag

    def handle_data(self, data):
        if self.stack and self.stack[-1] in ("td", "th", "a") and self.tables:
            self.tables[-1][-1][-1] += data


def _spec(world: str, seed: int, noise: float = 0.0) -> RunSpec:
    return RunSpec(f"{world}{seed}", f"/w/{world}.yaml", world, world, "no_furniture", "rbpf",
                   noise, seed, {})  # fmt: skip


def _records(tmp_path):
    report = tmp_path / "runs" / "a"
    report.mkdir(parents=True)
    (report / "map.png").write_bytes(b"\x89PNG")
    b = relation(stats(0.5, 0.25, 100), stats(0.01, 0.005, 100))
    good = make_summary(outcome="completed", reason=None, stop="no_frontier", coverage=0.9,
                        relations={"B": b}, timings={"sim_time_s": 123.4})  # fmt: skip
    crash = make_summary(outcome="failed", reason="collision", stop="collision",
                         coverage=0.25, relations={})  # fmt: skip
    return [
        record_of(_spec("<i>office</i>", 1), summary=good, report_dir=str(report)),
        record_of(_spec("office", 2, 0.3), summary=crash),
        record_of(_spec("office", 3), summary=None, error="ValueError: <script>x & 'y'"),
    ]


def test_the_runs_table_and_headline_hold_the_records_figures(tmp_path):
    recs = _records(tmp_path)
    info = {"batch_id": "b1", "command": "mapqual batch a & b"}
    page_path = write_html(recs, {"noise.png": None}, tmp_path, info, expected=4)
    text = page_path.read_text()
    page = _Page()
    page.feed(text)
    assert page.balanced and not page.stack
    runs = page.tables[-1]
    assert runs[0][:5] == ["world", "seed", "slam", "noise [m]", "outcome"]
    # coverage to 3 decimals, B means to 4, sim time to 0; a run with no B relations: 0; no
    # 95 % half-width in these summaries (written before it): a dash
    assert runs[1] == ["<i>office</i>", "1", "rbpf", "0", "completed", "0.900", "0.5000",
                       "0.0100", "–", "100", "123"]  # fmt: skip
    assert runs[2] == ["office", "2", "rbpf", "0.3", "failed (collision)", "0.250", "–", "–",
                       "–", "0", "300"]  # fmt: skip
    assert runs[3] == ["office", "3", "rbpf", "0", "failed (error): ValueError: <script>x & 'y'",
                       "–", "–", "–", "–", "0", "–"]  # fmt: skip
    assert page.links == ["runs/a/map.png"]  # relative to the page, only where a map exists
    assert "l good" in page.classes and page.classes.count("l bad") == 2
    assert "3 of 4 runs finished: 1 completed, 1 visually good" in " ".join(text.split())
    assert "<p><i>noise.png: not drawn (no world run at more than one noise level).</i></p>" in text


def test_everything_from_the_records_is_escaped(tmp_path):
    info = {"batch_id": "<b>", "command": 'x="1" & y'}
    text = write_html(_records(tmp_path), {}, tmp_path, info, expected=3).read_text()
    assert "<script>" not in text and "<i>office" not in text and "<b>" not in text
    assert "&lt;script&gt;x &amp; &#39;y&#39;" in text and "&lt;i&gt;office&lt;/i&gt;" in text
    assert "x=&#34;1&#34; &amp; y" in text


def test_the_template_ships_with_the_package():
    assert (files("worker.batch") / "templates" / "report.html").is_file()
