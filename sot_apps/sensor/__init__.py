"""The LiDAR sensor model, shared by every app that simulates or measures sweeps (floor under lidar_sim,
benchmark, synth, evaluation, bench).

Modules: ``model`` (a spinning LiDAR: beam table, columns, timing; the presets), ``scan`` (rolling-scan sweep
simulation over meshes with the Embree engine of :mod:`sot_apps.raycast`), ``noise`` (range noise, ray drop,
intensity), ``occlusion`` (simulated returns against real ones: who hides whom), ``preview`` (bird's-eye view
of a sweep), ``fit`` (a beam table and optical centre estimated from real sweeps, ``sot-apps sensor fit``).
"""
