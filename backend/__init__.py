"""The FastAPI service: settings, database, API routes."""
