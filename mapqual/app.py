"""The service's web application, assembled above both halves: the REST API
(`backend.api.app`) with the dashboard (`frontend.dashboard`) mounted at /.

`uvicorn mapqual.app:app` (or `mapqual serve`); tests build their own with `create_app`.
"""

from __future__ import annotations

from fastapi import FastAPI

from backend.api.app import create_api
from backend.core.config import Settings
from frontend.dashboard import install as install_dashboard


def create_app(settings: Settings | None = None) -> FastAPI:
    """The API with the dashboard at / (its catch-all pages come after the API's routes and the
    manual, since routes are matched in order)."""
    app = create_api(settings)
    install_dashboard(app)
    return app


app = create_app()
