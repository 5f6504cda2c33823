"""The synthetic driving world with exact ground truth (``sot-apps synth``): world, vehicles, camera rendering."""

from .world import BASE_TIME_NS, SENSOR_HEIGHT, SynthCamera, World, WorldObject, make_world, write_world

__all__ = ["WorldObject", "World", "SynthCamera", "make_world", "write_world", "SENSOR_HEIGHT", "BASE_TIME_NS"]
