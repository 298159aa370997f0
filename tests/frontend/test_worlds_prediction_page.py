"""The worlds page shows each ready world's predicted map quality and its features (issue 22)."""

from __future__ import annotations

from tests.frontend.test_pages import _png, _room, _signed_in, _wait_ready, site  # noqa: F401, F811


def test_worlds_page_shows_the_prediction_and_the_features(site):  # noqa: F811
    client = _signed_in(site, "b")
    occ = _room()
    occ[40, 20:100] = True
    client.post("/worlds", files={"file": ("hall.png", _png(occ))}, data={"resolution": "0.05"})
    wid = client.get("/api/v1/worlds").json()[0]["id"]
    _wait_ready(client, wid)
    page = client.get("/worlds").text
    api = client.get(f"/api/v1/worlds/{wid}/prediction").json()
    assert "predicted from the plan (rbpf, bundled model)" in page
    assert f"{api['b_mean_t']['median']:.3f} m" in page  # the page shows what the API says
    assert "floorplan features" in page and "mean area the laser sees from a point" in page
    assert "measured (" not in page  # no run yet
