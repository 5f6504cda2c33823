"""The tracker's strategies, one small module per concern; :mod:`tracker.strategies.choose` picks them from a
:class:`~tracker.config.TrackerConfig` once, when a :class:`~tracker.sotracker.Tracker` is made."""
