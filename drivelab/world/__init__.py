"""The bottom layer: what a world is (one WorldState, K worlds as a WorldBatch), the static road
map, and the plane geometry every layer above shares. Imports nothing from drivelab above it."""

from drivelab.world.batch import EgoBatch, EventsBatch, RouteBatch, WorldBatch
from drivelab.world.state import Ego, Events, RoadMap, Route, WorldState

__all__ = [
    "Ego", "EgoBatch", "Events", "EventsBatch", "RoadMap", "Route", "RouteBatch", "WorldBatch", "WorldState",
]  # fmt: skip
