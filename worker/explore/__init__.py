"""Autonomous exploration: costmaps, frontiers, navfn-like planner, DWA, safety, stop rules."""
