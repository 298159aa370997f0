"""The service's catalogue of bundled data sets on a folder of its own: loaded once, again only
for the data set whose files changed; thumbnails made once; an import stored once per owner."""

from __future__ import annotations

import io
import os

import pytest
from PIL import Image

from backend.core.config import Settings
from backend.db.models import World
from backend.db.session import session_scope
from backend.services.access import Principal
from backend.services.datasets import BundledCatalogue, import_bundled, imported_ids
from backend.services.errors import NotFound, QuotaExceeded
from backend.store import add_user
from tests.worker.world.test_datasets import write_plan


@pytest.fixture
def root(tmp_path):
    write_plan(tmp_path / "one", "a")
    write_plan(tmp_path / "one", "b", w=90)
    write_plan(tmp_path / "two", "c")
    return tmp_path


def test_the_catalogue_loads_once_and_again_only_what_changed(root):
    cat = BundledCatalogue(lambda: root, recheck_s=0.0)
    first = cat.datasets()
    assert [d.name for d in first] == ["one", "two"] and cat.loads == 2
    assert cat.datasets()[0] is first[0] and cat.loads == 2  # nothing changed: the same
    png = root / "one" / "b.png"
    st = png.stat()
    os.utime(png, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    again = cat.datasets()
    assert cat.loads == 3 and again[0] is not first[0] and again[1] is first[1]
    write_plan(root / "three", "d")
    assert [d.name for d in cat.datasets()] == ["one", "three", "two"] and cat.loads == 4


def test_the_files_are_looked_at_again_only_after_recheck_s(root):
    cat = BundledCatalogue(lambda: root, recheck_s=3600.0)
    cat.datasets()
    write_plan(root / "three", "d")
    assert [d.name for d in cat.datasets()] == ["one", "two"]  # within the hour: as it was


def test_names_are_looked_up_never_opened(root):
    cat = BundledCatalogue(lambda: root, recheck_s=0.0)
    assert cat.world("one", "a")[1].name == "a"
    for dataset, name in (("nope", "a"), ("one", "c"), ("one", "../two/c"), ("..", "one/a"),
                          ("one", "a.yaml"), ("one", str(root / "one" / "a"))):  # fmt: skip
        with pytest.raises(NotFound):  # 404 (backend.api.errors)
            cat.world(dataset, name)


def test_thumbnails_are_made_once_per_size_and_bounded(root):
    cat = BundledCatalogue(lambda: root, recheck_s=0.0, thumbnails_max=2)
    png = cat.thumbnail("one", "b", 30)
    assert cat.thumbnail("one", "b", 30) is png
    assert Image.open(io.BytesIO(png)).size == (30, 14)  # 90 x 40 px by a factor of 3
    full = Image.open(io.BytesIO(cat.thumbnail("one", "b", None)))
    assert full.size == (90, 40)
    cat.thumbnail("one", "a", 30)  # a third one: the least recently used goes
    assert cat.thumbnail("one", "b", 30) is not png


def test_an_import_is_stored_once_per_owner_ready_and_counted_by_the_quota(root, db_url):
    cat = BundledCatalogue(lambda: root, recheck_s=0.0)
    with session_scope(db_url) as s:
        users = [Principal.of(add_user(s, name)[0]) for name in ("ann", "ben")]
    settings = Settings(DATABASE_URL=db_url, MAPQUAL_QUOTA_WORLDS=1)
    ann, ben = users
    with session_scope(db_url) as s:
        row, fresh = import_bundled(s, ann, settings, "one", "a", cat)
        assert fresh and row.status == "ready" and row.name == "a"
        first = row.id
    with session_scope(db_url) as s:
        row, fresh = import_bundled(s, ann, settings, "one", "a", cat)
        assert (row.id, fresh) == (first, False)  # the same content: the same world
        other, fresh = import_bundled(s, ben, settings, "one", "a", cat)
        assert fresh and other.id != first and other.owner_id == ben.id
        w = cat.world("one", "a")[1]
        assert imported_ids(s, ann) == {w.fingerprint: first}
    with session_scope(db_url) as s, pytest.raises(QuotaExceeded) as exc:
        import_bundled(s, ann, settings, "one", "b", cat)  # a second world: over the quota
    assert "quota_worlds" in exc.value.detail
    with session_scope(db_url) as s:
        stored = s.get_one(World, first)
        assert stored.sha256 == w.fingerprint and stored.source_format == "yaml"
        assert stored.width_px == 60 and stored.facts["free_area_m2"] > 0
        assert s.query(World).count() == 2
