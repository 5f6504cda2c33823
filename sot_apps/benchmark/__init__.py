"""A LiDAR-SOT benchmark you can generate (``sot-apps benchmark make``), LiDAR-SOT-style tracklet lists
(``benchmark build``) and their evaluation (``sot-apps eval --benchmark``). See docs/benchmark.md."""
