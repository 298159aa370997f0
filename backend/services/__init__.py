"""The service layer: what the API routes, the dashboard, the CLI, batch and the worker call."""
