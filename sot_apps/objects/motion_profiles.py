"""Vehicle motion profiles with realistic dynamics: a kinematic bicycle with bounded acceleration, jerk,
steering angle and steering rate.

Shared by the synthetic world (``sot-apps synth --profiles``) and the generated LiDAR-SOT benchmark
(``sot-apps benchmark make``). A profile is drawn once (:func:`sample_motion`: speeds, times, targets as
numbers in a :class:`MotionSpec`) and integrated deterministically (:func:`integrate_motion`) in a LOCAL
frame: the vehicle starts at the origin heading along +x. Callers place the path with a rigid 2D transform.

Dynamics (reference point = box centre, rear axle at ``wheelbase / 2`` behind it)::

    a'     = clip(a_cmd - a, +-max_jerk * dt) / dt,   a in [-max_decel, max_accel]
    delta' = clip(delta_cmd - delta, +-max_steer_rate * dt) / dt,   |delta| <= max_steer
    beta   = atan(tan(delta) / 2)
    x' = v cos(psi + beta),  y' = v sin(psi + beta),  psi' = 2 v sin(beta) / wheelbase,  v = max(v + a dt, 0)

Profiles (:data:`PROFILES`):

- ``constant_speed``: 1-25 m/s;
- ``hard_brake``: cruise 8-20 m/s, then brake at 5-8 m/s^2 to a stop and stay;
- ``strong_accel``: from 0-6 m/s accelerate at 3-4.5 m/s^2 (up to 25 m/s);
- ``stop_and_go``: cruise 6-12 m/s, brake at 3-5 m/s^2 to a stop, wait 0.3-1 s, accelerate at 2-3.5 m/s^2;
- ``lane_change``: 6-20 m/s, a sinusoidal steer that shifts the vehicle 3-3.7 m sideways in 2-3.5 s;
- ``turn``: 4-9 m/s, steer until the heading has turned 90 deg (left or right), then straighten;
- ``u_turn``: 2.5-5 m/s, full lock until the heading has turned 180 deg, then straighten;
- ``occluded``: 3-12 m/s at constant speed; the benchmark adds another vehicle that crosses the line of
  sight (the profile describes the target's motion; the occluder is the benchmark's job).

The profiles that provoke what fails on unseen vehicles (:data:`HARD_PROFILES`; the geometry relative to the
sensor, which the profile alone cannot fix, is the benchmark's job: ``sot_apps.benchmark.placement``):

- ``far_approach``: 5-12 m/s at constant speed; placed >= 55 m away and driving towards the sensor;
- ``passing``: 7-14 m/s at constant speed; placed so that it drives past the sensor;
- ``hidden``: 3-10 m/s at constant speed; the benchmark removes its points for 5-15 frames;
- ``oblique``: 3-9 m/s, straight or gently curving (a constant steer of at most 0.02 rad, a radius of at
  least 140 m); placed so that the sensor sees it from behind-side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["PROFILES", "HARD_PROFILES", "ALL_PROFILES", "VehicleLimits", "MotionSpec", "MotionPath", "sample_motion",
           "integrate_motion", "place_path", "place_states"]

PROFILES: tuple[str, ...] = ("constant_speed", "hard_brake", "strong_accel", "stop_and_go", "lane_change", "turn",
                             "u_turn", "occluded")
HARD_PROFILES: tuple[str, ...] = ("far_approach", "passing", "hidden", "oblique")
ALL_PROFILES: tuple[str, ...] = PROFILES + HARD_PROFILES


@dataclass(frozen=True)
class VehicleLimits:
    """Bounds of the bicycle model (m, s, rad)."""

    wheelbase: float = 2.8
    max_accel: float = 5.0
    max_decel: float = 8.0
    max_jerk: float = 15.0
    max_steer: float = 0.55
    max_steer_rate: float = 0.8
    max_speed: float = 25.0


@dataclass(frozen=True)
class MotionSpec:
    """One drawn profile: the name, the initial speed and the profile's numbers (see the module doc)."""

    profile: str
    speed0: float
    params: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"profile": self.profile, "speed0": round(self.speed0, 4),
                **{k: round(float(v), 4) for k, v in sorted(self.params.items())}}


@dataclass(frozen=True)
class MotionPath:
    """The integrated path in the local frame: per sample time (s from the start), x, y, heading, speed, accel."""

    times_s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    accel: np.ndarray

    def states(self) -> np.ndarray:
        """(T, 3) x, y, heading."""
        return np.stack([self.x, self.y, self.heading], axis=1)


def sample_motion(profile: str, rng: np.random.Generator, duration_s: float) -> MotionSpec:
    """Draw the numbers of ``profile`` for a path of ``duration_s`` seconds."""
    u = rng.uniform
    event = lambda: float(u(0.15, 0.45) * duration_s)  # noqa: E731 - when the manoeuvre starts
    side = float(rng.choice([-1.0, 1.0]))
    if profile == "constant_speed":
        return MotionSpec(profile, float(u(1.0, 25.0)))
    if profile == "hard_brake":
        return MotionSpec(profile, float(u(8.0, 20.0)), {"t_brake": event(), "decel": float(u(5.0, 8.0))})
    if profile == "strong_accel":
        return MotionSpec(profile, float(u(0.0, 6.0)), {"t_accel": float(u(0.0, 0.25) * duration_s),
                                                        "accel": float(u(3.0, 4.5))})
    if profile == "stop_and_go":
        return MotionSpec(profile, float(u(6.0, 12.0)), {"t_brake": float(u(0.05, 0.2) * duration_s),
                                                         "decel": float(u(3.0, 5.0)), "wait": float(u(0.3, 1.0)),
                                                         "accel": float(u(2.0, 3.5))})
    if profile == "lane_change":
        return MotionSpec(profile, float(u(6.0, 20.0)), {"t_start": event(), "offset": side * float(u(3.0, 3.7)),
                                                         "duration": float(u(2.0, 3.5))})
    if profile == "turn":
        return MotionSpec(profile, float(u(4.0, 9.0)), {"t_start": event(), "angle": side * math.pi / 2,
                                                        "steer": float(u(0.25, 0.45))})
    if profile == "u_turn":
        return MotionSpec(profile, float(u(2.5, 5.0)), {"t_start": float(u(0.05, 0.3) * duration_s),
                                                        "angle": side * math.pi, "steer": 0.55})
    if profile == "occluded":
        return MotionSpec(profile, float(u(3.0, 12.0)))
    if profile == "far_approach":
        return MotionSpec(profile, float(u(5.0, 12.0)))
    if profile == "passing":
        return MotionSpec(profile, float(u(7.0, 14.0)))
    if profile == "hidden":
        return MotionSpec(profile, float(u(3.0, 10.0)))
    if profile == "oblique":
        return MotionSpec(profile, float(u(3.0, 9.0)), {"steer": side * float(u(0.0, 0.02))})
    raise ValueError(f"unknown motion profile {profile!r}; known: {', '.join(ALL_PROFILES)}")


def _brake(v: float, decel: float, limits: VehicleLimits) -> float:
    """Braking command that releases the brake as the car stops, so the jerk bound holds at the stop."""
    return -min(decel, math.sqrt(limits.max_jerk * max(v, 0.0)))


def _commands(spec: MotionSpec, t: float, v: float, turned: float, state: dict, limits: VehicleLimits
              ) -> tuple[float, float]:
    """(acceleration command, steering command) at time t (``state`` carries the stop-and-go phase)."""
    p = spec.params
    name = spec.profile
    if name == "hard_brake":
        return (_brake(v, p["decel"], limits) if t >= p["t_brake"] else 0.0), 0.0
    if name == "strong_accel":
        return (p["accel"] if t >= p["t_accel"] else 0.0), 0.0
    if name == "stop_and_go":
        if t < p["t_brake"]:
            return 0.0, 0.0
        if "stopped_at" not in state:
            if v > 1e-3:
                return _brake(v, p["decel"], limits), 0.0
            state["stopped_at"] = t
        return (p["accel"] if t >= state["stopped_at"] + p["wait"] else 0.0), 0.0
    if name == "lane_change":
        t0, period = p["t_start"], p["duration"]
        if not t0 <= t < t0 + period:
            return 0.0, 0.0
        # offset = v^2 A T^2 / (2 pi L) for a steer A sin(2 pi t / T) at speed v (small angles)
        amplitude = 2.0 * math.pi * limits.wheelbase * p["offset"] / (max(spec.speed0, 1.0) ** 2 * period ** 2)
        return 0.0, min(max(amplitude, -limits.max_steer), limits.max_steer) * math.sin(2 * math.pi * (t - t0) / period)
    if name in ("turn", "u_turn"):
        if t < p["t_start"]:
            return 0.0, 0.0
        # steer until the heading has turned to within the distance the steering needs to straighten
        remaining = abs(p["angle"]) - abs(turned)
        unwind = p["steer"] / limits.max_steer_rate  # seconds to bring the wheel back
        rate = v * math.tan(p["steer"]) / limits.wheelbase
        steering = remaining > 0.5 * rate * unwind
        return 0.0, (math.copysign(p["steer"], p["angle"]) if steering else 0.0)
    if name == "oblique":
        return 0.0, p["steer"]
    return 0.0, 0.0  # constant_speed, occluded, far_approach, passing, hidden


def integrate_motion(spec: MotionSpec, duration_s: float, dt: float = 0.01,
                     limits: VehicleLimits = VehicleLimits()) -> MotionPath:
    """Integrate ``spec`` from the origin (heading +x) for ``duration_s`` at step ``dt`` (deterministic)."""
    n = int(round(duration_s / dt)) + 1
    rows = []
    x = y = psi = 0.0
    a = 0.0
    delta = 0.0
    v = min(max(spec.speed0, 0.0), limits.max_speed)
    state: dict = {}
    jerk_step, steer_step = limits.max_jerk * dt, limits.max_steer_rate * dt
    for i in range(n):  # a few hundred steps per path
        t = i * dt
        rows.append((t, x, y, psi, v, a))
        a_cmd, d_cmd = _commands(spec, t, v, psi, state, limits)
        if a_cmd > 0.0:  # ease off before the top speed, as the brake eases off before a stop
            a_cmd = min(a_cmd, math.sqrt(limits.max_jerk * max(limits.max_speed - v, 0.0)))
        a += min(max(a_cmd - a, -jerk_step), jerk_step)  # python floats: np.clip per step costs 10x the step
        a = min(max(a, -limits.max_decel), limits.max_accel)
        delta += min(max(d_cmd - delta, -steer_step), steer_step)
        delta = min(max(delta, -limits.max_steer), limits.max_steer)
        beta = math.atan(math.tan(delta) / 2.0)
        x += v * math.cos(psi + beta) * dt
        y += v * math.sin(psi + beta) * dt
        psi += 2.0 * v * math.sin(beta) / limits.wheelbase * dt
        v_new = v + a * dt
        if v_new <= 0.0:  # stopped: no reversing
            v_new, a = 0.0, max(a, 0.0)
        v = min(v_new, limits.max_speed)
    out = np.array(rows, dtype=np.float64)
    return MotionPath(out[:, 0], out[:, 1], out[:, 2], out[:, 3], out[:, 4], out[:, 5])


def place_states(local: np.ndarray, x0: float, y0: float, heading0: float) -> np.ndarray:
    """(T, 3) world x, y, heading of local (T, 3) x, y, heading states started at (x0, y0) heading ``heading0``."""
    c, s = math.cos(heading0), math.sin(heading0)
    return np.stack([x0 + c * local[:, 0] - s * local[:, 1], y0 + s * local[:, 0] + c * local[:, 1],
                     (local[:, 2] + heading0 + np.pi) % (2 * np.pi) - np.pi], axis=1)


def place_path(path: MotionPath, x0: float, y0: float, heading0: float) -> np.ndarray:
    """(T, 3) world x, y, heading of a local path started at (x0, y0) heading ``heading0``."""
    return place_states(path.states(), x0, y0, heading0)
