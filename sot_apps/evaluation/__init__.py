"""Evaluation (pure functions; configs as data)."""
