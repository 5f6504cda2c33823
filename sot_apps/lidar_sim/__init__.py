"""LiDAR simulation: sensors, the rolling scan, realism, the vehicle bank (ray casting: sot_apps.raycast; the synthetic world: sot_apps.synth)."""
