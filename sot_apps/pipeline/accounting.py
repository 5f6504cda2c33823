"""Where a run's time went, per worker and for the run's own process: from the tracking tasks' schedule
(``PipelineResult.track_schedule``, also in ``manifest.json``) and the run's phases (``PipelineResult.phases``).

Per worker (one process id): its tasks, when its first task started after the stage began (start-up: the worker's
process creation, imports not preloaded, the task's hand-over), its busy wall seconds, the tasks' CPU seconds
(their thread and writer thread), the worker process's CPU during its tasks (beyond the tasks' own: what else the
worker runs meanwhile, e.g. Dask's event loop), the wait (busy wall minus the process's CPU: not on a CPU while
running a task, i.e. the machine was busy, or the disk), the idle time (the stage's wall minus busy: waiting for
work or for the others to finish), and the sweep reading (read + ground mask, the part chunking repeats).

The schedule's bound: the busiest worker's task CPU against the tasks' CPU spread evenly over the workers (the
chunks' balance) and against the costliest object (no chunking can go below it).
"""

from __future__ import annotations

import os

__all__ = ["process_age", "worker_accounting", "schedule_balance", "main_accounting", "predicted_makespan",
           "format_accounting"]


def worker_accounting(schedule: dict) -> list[dict]:
    """One row per worker process of ``schedule`` (see module doc), busiest first."""
    wall = float(schedule.get("wall_s", 0.0))
    by_pid: dict[int, list[dict]] = {}
    for task in schedule.get("tasks", []):
        if "pid" in task:
            by_pid.setdefault(task["pid"], []).append(task)
    rows = []
    for pid, tasks in by_pid.items():
        tasks.sort(key=lambda t: t["start_s"])
        busy = sum(t["end_s"] - t["start_s"] for t in tasks)
        process_cpu = sum(t["process_cpu_s"] for t in tasks)
        rows.append({"pid": pid, "tasks": len(tasks), "objects": sum(len(t["objects"]) for t in tasks),
                     "first_start_s": round(tasks[0]["start_s"], 3), "last_end_s": round(tasks[-1]["end_s"], 3),
                     "busy_s": round(busy, 3), "idle_s": round(max(0.0, wall - busy), 3),
                     "task_cpu_s": round(sum(t["cpu_s"] for t in tasks), 3),
                     "process_cpu_s": round(process_cpu, 3),
                     "wait_s": round(max(0.0, busy - process_cpu), 3),
                     "startup_cpu_s": round(tasks[0]["process_cpu_before_s"], 3),
                     "open_cpu_s": round(sum(t["open_cpu_s"] for t in tasks), 3),
                     "sweep_read_s": round(sum(t["read_s"] + t["ground_s"] for t in tasks), 3),
                     "sweeps": int(sum(t["sweeps"] for t in tasks)),
                     "object_frames": int(sum(t["object_frames"] for t in tasks)),
                     "object_frames_per_s": round(sum(t["object_frames"] for t in tasks) / busy, 2) if busy else 0.0})
    return sorted(rows, key=lambda r: -r["task_cpu_s"])


def schedule_balance(schedule: dict, workers: int) -> dict:
    """The tasks' CPU seconds, the busiest worker's, the even share (total / workers) and the costliest object's;
    ``balance`` = busiest / even share (1.0: the chunks split the work evenly)."""
    tasks = [t for t in schedule.get("tasks", []) if "pid" in t]
    total = sum(t["cpu_s"] for t in tasks)
    rows = worker_accounting(schedule)
    busiest = max((r["task_cpu_s"] for r in rows), default=0.0)
    objects = [cpu for t in tasks if isinstance(t["objects"], dict) for cpu in t["objects"].values()]
    even = total / max(1, workers)
    return {"tasks": len(tasks), "task_cpu_s": round(total, 3), "busiest_worker_cpu_s": round(busiest, 3),
            "even_share_s": round(even, 3), "costliest_object_s": round(max(objects, default=0.0), 3),
            "balance": round(busiest / even, 3) if even else None}


def main_accounting(phases: dict, startup: bool = True) -> dict:
    """The run's own process: its start-up before the run (interpreter, imports: wall and CPU), planning, the
    workers' preparation (Dask: the cluster and every worker opening the sequences), the tracking stage's wall and
    this process's CPU meanwhile (scheduling, collecting results; Dask's scheduler and nannies live here), and
    the end (apps, manifest). ``startup=False``: a run inside a longer process (a benchmark), whose age says
    nothing about the run."""
    def at(name: str) -> float:
        return float(phases.get(name, {}).get("at_s", 0.0))

    def cpu(name: str) -> float:
        return float(phases.get(name, {}).get("cpu_s", 0.0))

    if "started" not in phases:
        return {}
    return {"startup_wall_s": round(-at("started"), 3) if startup else None,
            "startup_cpu_s": round(cpu("started"), 3) if startup else None, "plan_wall_s": round(at("planned"), 3), "plan_cpu_s": round(cpu("planned") - cpu("started"), 3),
            "open_wall_s": round(at("opened") - at("planned"), 3), "open_cpu_s": round(cpu("opened") - cpu("planned"), 3),
            "track_wall_s": round(at("tracked") - at("opened"), 3),
            "track_cpu_s": round(cpu("tracked") - cpu("opened"), 3),
            "end_wall_s": round(at("finished") - at("tracked"), 3), "end_cpu_s": round(cpu("finished") - cpu("tracked"), 3)}


def predicted_makespan(schedule: dict, phases: dict, workers: int) -> dict:
    """The run's wall seconds (start-up included) if every process had a core of its own and a CPU second bought the
    work it bought in this run: from CPU seconds only, so a run measured on a loaded machine still says what the
    schedule allows. The run's process first spends ``serial_s`` (its start-up, planning and cost estimate: its CPU
    when the first batch began); a worker process is ready once that is done and its fork server is ready (the
    run's CPU when it started the server plus the server's CPU for its imports and opening the sequences:
    ``server_s``), plus the worker's own start-up CPU (its first task's ``process_cpu_before_s``); tasks run on one
    core at a time, for their CPU, handed out in the schedule's order to the worker free first (as the executors
    do); then the run's end (its CPU after the stage). A run whose tasks ran in its own process (1 worker) starts
    them at its CPU at the first task (the tracking imports included). ``even_s``: the same with the tasks' CPU
    spread evenly over the workers (perfect balance): the gap to ``makespan_s`` is the tail."""
    tasks = [t for t in schedule.get("tasks", []) if "pid" in t]
    if not tasks or "opened" not in phases:
        return {}
    serial = float(phases["opened"]["cpu_s"]) + float(schedule.get("chunking_cpu_s", 0.0))
    run_pid = schedule.get("run_pid")
    first: dict[int, dict] = {}
    for t in sorted(tasks, key=lambda t: t["start_s"]):
        first.setdefault(t["pid"], t)
    server = None
    if all(pid == run_pid for pid in first):   # inline: the run's own process tracks
        workers, ready = 1, float(tasks[0]["process_cpu_before_s"])
    else:
        ready_cpu = [t["server_ready_cpu_s"] for t in first.values() if "server_ready_cpu_s" in t]
        if ready_cpu and "server_started" in phases:
            server = float(phases["server_started"]["cpu_s"]) + max(ready_cpu)
        startup = sorted(t["process_cpu_before_s"] for t in first.values())[len(first) // 2]
        ready = max(serial, server or 0.0) + startup
    free = [ready] * max(1, workers)
    for t in tasks:   # the schedule lists them in the order they were handed out
        i = min(range(len(free)), key=free.__getitem__)
        free[i] += float(t["cpu_s"])
    end = max(0.0, float(phases.get("finished", phases["opened"])["cpu_s"])
              - float(phases.get("tracked", phases["opened"])["cpu_s"]))
    total = sum(float(t["cpu_s"]) for t in tasks)
    return {"serial_s": round(serial, 3), "server_s": round(server, 3) if server is not None else None,
            "first_task_s": round(ready, 3), "tasks_cpu_s": round(total, 3), "end_s": round(end, 3),
            "makespan_s": round(max(free) + end, 3), "even_s": round(ready + total / max(1, workers) + end, 3)}


def format_accounting(schedule: dict, phases: dict, workers: int, startup: bool = True) -> str:
    """The three accountings as text (``sot-apps bench pipeline`` prints one block per configuration)."""
    lines = ["| worker | tasks | objects | object-frames/s (busy) | first task at s | busy s | idle s | task CPU s "
             "| process CPU s | wait s | start-up CPU s | open CPU s | sweep read s (sweeps) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for i, r in enumerate(worker_accounting(schedule)):
        lines.append(f"| {i + 1} (pid {r['pid']}) | {r['tasks']} | {r['objects']} | {r['object_frames_per_s']:.1f} | "
                     f"{r['first_start_s']:.2f} | "
                     f"{r['busy_s']:.2f} | {r['idle_s']:.2f} | {r['task_cpu_s']:.2f} | {r['process_cpu_s']:.2f} | "
                     f"{r['wait_s']:.2f} | {r['startup_cpu_s']:.2f} | {r['open_cpu_s']:.2f} | "
                     f"{r['sweep_read_s']:.2f} ({r['sweeps']}) |")
    b = schedule_balance(schedule, workers)
    lines.append(f"\nschedule: {b['tasks']} tasks, {b['task_cpu_s']:.2f} s task CPU; busiest worker {b['busiest_worker_cpu_s']:.2f} s "
                 f"against an even share of {b['even_share_s']:.2f} s (balance {b['balance'] or 0:.2f}); costliest "
                 f"object {b['costliest_object_s']:.2f} s; tasks' wall {float(schedule.get('wall_s', 0.0)):.2f} s, after "
                 f"chunking {float(schedule.get('chunking_s', 0.0)):.2f} s ({float(schedule.get('chunking_cpu_s', 0.0)):.2f} "
                 "s CPU: the cost estimate)")
    p = predicted_makespan(schedule, phases, workers)
    if p and startup:
        lines.append(f"predicted wall with a core per process (CPU seconds only): {p['makespan_s']:.2f} s = run's "
                     f"process {p['serial_s']:.2f} s" + (f", fork server ready at {p['server_s']:.2f} s"
                                                         if p["server_s"] is not None else "")
                     + f", first task at {p['first_task_s']:.2f} s, {p['tasks_cpu_s']:.2f} s of tasks over {workers} "
                     f"worker(s) (evenly: {p['even_s']:.2f} s), end {p['end_s']:.2f} s")
    m = main_accounting(phases, startup)
    if m:
        begin = (f"start-up {m['startup_wall_s']:.2f} s wall ({m['startup_cpu_s']:.2f} s CPU), " if startup else "")
        lines.append(f"run's process: {begin}"
                     f"plan {m['plan_wall_s']:.2f} s ({m['plan_cpu_s']:.2f}), workers' preparation "
                     f"{m['open_wall_s']:.2f} s ({m['open_cpu_s']:.2f}), tracking {m['track_wall_s']:.2f} s "
                     f"({m['track_cpu_s']:.2f} s CPU in this process meanwhile), end {m['end_wall_s']:.2f} s "
                     f"({m['end_cpu_s']:.2f})")
    return "\n".join(lines)


def process_age() -> float:
    """Seconds since this process started (Linux: /proc; 0 where unknown): for the run's process its interpreter
    start-up and imports; for a worker forked from the fork server, the time since its fork."""
    try:
        with open("/proc/self/stat") as f:
            start_ticks = float(f.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
        return round(max(0.0, uptime - start_ticks / os.sysconf("SC_CLK_TCK")), 3)
    except (OSError, ValueError, IndexError, AttributeError):
        return 0.0
