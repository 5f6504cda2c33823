"""LiDAR simulation: sensors, Embree ray casting, realism, the vehicle bank, and the synthetic world."""
