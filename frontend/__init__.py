"""The viser live viewer and the dashboard pages."""
