"""Data-generation pipelines: tracking -> bank -> motion export -> flow -> simulated scans."""

# what a worker imports for the tracking stage (its tasks run sot_apps.pipeline.stages; the tracker's modules load
# lazily, so they are named too): the fork server its workers are forked from imports them once
# (:meth:`sot_apps.pipeline.executors.ExecutorSession.prestart`, which `sot-apps run` calls before its own imports);
# last sot_apps.pipeline.warm, which opens the run's sequences in the server when the run names them
WORKER_MODULES = ("sot_apps.pipeline.stages", "tracker.sotracker", "tracker.offline", "sot_apps.io.sweep_cache",
                  "sot_apps.pipeline.warm")
