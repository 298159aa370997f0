"""GET /worlds/{id}/prediction against a real database: the bundled model's prediction of an
uploaded plan, its measured errors once runs are stored, 4xx for what cannot be predicted."""

from __future__ import annotations

import numpy as np

from tests.backend.api.test_worlds_jobs import _png, _upload
from tests.summaries import make_summary, relation, stats


def test_prediction_of_an_uploaded_plan_then_with_a_measured_run(api):
    w = _upload(api, [("box.png", _png(), "image/png")], resolution="0.05").json()
    r = api.get(f"/api/v1/worlds/{w['id']}/prediction")
    assert r.status_code == 200, r.text
    p = r.json()
    assert p["world_id"] == w["id"] and p["slam"] == "rbpf"
    assert 0 < p["b_mean_t"]["low"] <= p["b_mean_t"]["median"] <= p["b_mean_t"]["high"]
    # the plan: 78 x 58 free pixels at 0.05 m less the middle wall's 58 - 20 = 38 pixels
    assert p["features"]["free_area_m2"] == np.float64((78 * 58 - 38) * 0.05**2)
    assert p["features"]["n_rooms"] == 2 and p["measured"]["runs"] == 0

    from backend.db.session import session_scope
    from backend.store import mark_run_started, store_run_result

    body = {"world_id": w["id"], "runs": 2, "slam": "rbpf"}
    run_ids = [x["id"] for x in api.post("/api/v1/jobs", json=body).json()["runs"]]
    for run_id, mean_t in zip(run_ids, (0.2, 0.4), strict=True):
        summary = make_summary(
            outcome="completed", reason=None, coverage=0.9,
            relations={"B": relation(stats(mean_t, 0.1, 9), stats(0.01, 0.001, 9))},
        )  # fmt: skip
        with session_scope(api.url) as s:
            mark_run_started(s, run_id)
            store_run_result(
                s, run_id, summary=summary, t=np.arange(3) * 0.1, pose_gt=np.zeros((3, 3)),
                pose_est=np.zeros((3, 3)), map_ros=np.zeros((4, 4), np.int8),
                map_resolution=0.05, map_origin=(0.0, 0.0), report_dir=None,
            )  # fmt: skip
    m = api.get(f"/api/v1/worlds/{w['id']}/prediction").json()["measured"]
    assert m["runs"] == 2 and abs(m["b_mean_t"] - 0.3) < 1e-12


def test_prediction_refusals(api):
    w = _upload(api, [("box.png", _png(), "image/png")], resolution="0.05").json()
    r = api.get(f"/api/v1/worlds/{w['id']}/prediction", params={"slam": "nope"})
    assert r.status_code == 400 and "no 'nope' part" in r.json()["detail"]
    assert api.get("/api/v1/worlds/999999/prediction").status_code == 404
    assert api.get(f"/api/v1/worlds/{w['id']}/prediction", user="bob").status_code == 404
