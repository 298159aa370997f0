"""The one map from the services' typed errors to HTTP: each kind's status, the body FastAPI
gives an HTTPException, and the dashboard's error page for a browser."""

from __future__ import annotations

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from backend.api import errors
from backend.services.errors import (
    Conflict,
    Invalid,
    NotFound,
    QuotaExceeded,
    ServiceError,
    TooLarge,
    Unavailable,
)


@pytest.mark.parametrize(
    ("kind", "code"),
    [(Invalid, 400), (NotFound, 404), (Conflict, 409), (TooLarge, 413), (QuotaExceeded, 429),
     (Unavailable, 503), (ServiceError, 400)],
)  # fmt: skip
def test_each_kind_answers_its_status_with_the_detail_as_fastapi_writes_it(kind, code):
    app = FastAPI()
    errors.install(app)

    @app.get("/x")
    def refuse() -> None:
        raise kind("no world with id 7", headers={"Retry-After": "5"})

    r = TestClient(app).get("/x")
    assert r.status_code == code
    assert r.json() == {"detail": "no world with id 7"}
    assert r.headers["retry-after"] == "5"
