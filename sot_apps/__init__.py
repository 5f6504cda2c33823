"""sot-apps: data generation from LiDAR sequences with a model-free single-object tracker."""

__version__ = "0.1.0"
