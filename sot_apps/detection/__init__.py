"""Detections for tracking and auto-labelling: simulated detections, a model-free detector, auto-labels."""
