"""Floorplans: loading (image, map_server YAML, Stage .world), validation, start pose, facts."""

from worker.world.loader import load_world
from worker.world.world import World, WorldFacts

__all__ = ["World", "WorldFacts", "load_world"]
