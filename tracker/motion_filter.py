"""A CTRV motion model (constant turn rate and velocity) as an extended Kalman filter, and a slow height filter.

State s = [x, y, heading, speed, turn_rate] of the box centre (world frame, metres, radians, m/s, rad/s).
``predict(dt)`` moves it along a circular arc for ``dt`` SECONDS (not frames, so a gap of several frames is
predicted correctly); process noise is white longitudinal acceleration (``accel_sigma``, m/s²) and yaw
acceleration (``yaw_accel_sigma``, rad/s²) over the interval.

Measurements:

- ``update_heading(theta, sigma)``: a heading (the registration's box heading, or the direction of travel);
  angles are folded to the nearest representative of the state's heading;
- ``update_position(xy, sigma)``: the box centre.

The direction of travel is a heading measurement in its own right (``travel_heading``): the displacement
of the object's visible points between two frames (well constrained by the data even when the box's
rotation is not) points along the heading when the vehicle moves. Its noise grows as the displacement
shrinks (two position errors over a short baseline) and it is skipped below ``min_travel``; a reversing
vehicle is handled by folding the direction by pi.

:class:`HeightFilter` estimates the box's height above the road slowly: z is a random walk measured by the
registration's z (noisy, drifts with the fit) and, where a road plane is found, by road + a slowly
averaged offset (the road as a prior).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .geometry import Box, wrap_angle
from .motion import MotionPrior
from .speed_ramp import SpeedRamp
from .terms import apply_motion

__all__ = ["CTRVParams", "CTRVFilter", "ctrv_arc", "ctrv_predict_state", "travel_heading", "HeightFilter",
           "CTRVMotion", "AverageMotion"]


@dataclass(frozen=True)
class CTRVParams:
    accel_sigma: float = 4.0          # m/s^2, longitudinal acceleration noise
    yaw_accel_sigma: float = 3.0      # rad/s^2, turn-rate change noise
    position_sigma: float = 0.1       # m, process noise on the centre per sqrt(s) (model mismatch)
    initial_speed_sigma: float = 10.0  # m/s, before any motion was seen
    initial_turn_sigma: float = 0.3   # rad/s


def _f1_f2(a: float) -> tuple[float, float, float, float]:
    """f1 = sin(a)/a, f2 = (1 - cos a)/a and their derivatives (series near 0)."""
    if abs(a) < 1e-3:
        a2 = a * a
        return 1.0 - a2 / 6.0, a / 2.0 - a * a2 / 24.0, -a / 3.0 + a * a2 / 30.0, 0.5 - a2 / 8.0
    s, c = np.sin(a), np.cos(a)
    return s / a, (1.0 - c) / a, (a * c - s) / (a * a), (a * s - (1.0 - c)) / (a * a)


def ctrv_arc(course: float, speed: float, turn_rate: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The CTRV model (constant turn rate and velocity): the displacement (dx, dy) after ``dt`` seconds of moving
    at ``speed`` along ``course`` (the direction of travel at the start) while it turns at ``turn_rate`` (an
    exact circular arc, a straight line at zero turn rate), and its (2, 3) Jacobian d(dx, dy)/d(course, speed,
    turn_rate). The one CTRV model of the project (the tracker's filter and the motion export's smoother)."""
    f1, f2, d1, d2 = _f1_f2(turn_rate * dt)
    c, s = np.cos(course), np.sin(course)
    along, across = c * f1 - s * f2, s * f1 + c * f2
    dx, dy = speed * dt * along, speed * dt * across
    jac = np.array([[-dy, dt * along, speed * dt * dt * (c * d1 - s * d2)],
                    [dx, dt * across, speed * dt * dt * (s * d1 + c * d2)]])
    return np.array([dx, dy]), jac


def ctrv_predict_state(s: np.ndarray, dt: float) -> np.ndarray:
    """The CTRV state [x, y, heading, speed, turn_rate] after ``dt`` seconds (:func:`ctrv_arc`)."""
    x, y, th, v, w = s
    (dx, dy), _ = ctrv_arc(th, v, w, dt)
    return np.array([x + dx, y + dy, th + w * dt, v, w])


def _ctrv_jacobian(s: np.ndarray, dt: float) -> np.ndarray:
    """d(predict)/d(state), central differences (5 states: cheap and exact enough)."""
    jac = np.empty((5, 5))
    for i, h in enumerate((1e-4, 1e-4, 1e-6, 1e-4, 1e-6)):
        e = np.zeros(5)
        e[i] = h
        jac[:, i] = (ctrv_predict_state(s + e, dt) - ctrv_predict_state(s - e, dt)) / (2 * h)
    return jac


class CTRVFilter:
    """Extended Kalman filter over [x, y, heading, speed, turn_rate]."""

    def __init__(self, x: float, y: float, heading: float, params: CTRVParams = CTRVParams()) -> None:
        self.params = params
        self.s = np.array([x, y, heading, 0.0, 0.0])
        self.P = np.diag([1e-4, 1e-4, 1e-4, params.initial_speed_sigma ** 2, params.initial_turn_sigma ** 2])

    @property
    def heading(self) -> float:
        return float(self.s[2])

    @property
    def speed(self) -> float:
        return float(self.s[3])

    @property
    def turn_rate(self) -> float:
        return float(self.s[4])

    def predicted(self, dt: float) -> np.ndarray:
        """The state ``dt`` seconds ahead (the filter is not changed)."""
        return ctrv_predict_state(self.s, dt)

    def predict(self, dt: float) -> None:
        p = self.params
        dt = max(float(dt), 0.0)
        f = _ctrv_jacobian(self.s, dt)
        c, s = np.cos(self.s[2]), np.sin(self.s[2])
        g = np.array([[0.5 * dt * dt * c, 0.0], [0.5 * dt * dt * s, 0.0], [0.0, 0.5 * dt * dt], [dt, 0.0], [0.0, dt]])
        q = g @ np.diag([p.accel_sigma ** 2, p.yaw_accel_sigma ** 2]) @ g.T
        q[0, 0] += p.position_sigma ** 2 * dt
        q[1, 1] += p.position_sigma ** 2 * dt
        self.s = ctrv_predict_state(self.s, dt)
        self.P = f @ self.P @ f.T + q

    def position_sigma(self) -> float:
        """Standard deviation of the centre (the larger principal axis), metres."""
        return float(np.sqrt(max(np.linalg.eigvalsh(self.P[:2, :2])[-1], 0.0)))

    def _update(self, h: np.ndarray, residual: np.ndarray, r: np.ndarray) -> None:
        s_mat = h @ self.P @ h.T + r
        gain = self.P @ h.T @ np.linalg.inv(s_mat)
        self.s = self.s + gain @ residual
        i_kh = np.eye(5) - gain @ h
        self.P = i_kh @ self.P @ i_kh.T + gain @ r @ gain.T  # Joseph form: stays symmetric positive

    def update_heading(self, theta: float, sigma: float, fold_pi: bool = False, age: float = 0.0) -> None:
        """Heading measurement of ``age`` seconds ago (the heading then: theta - turn_rate * age); ``fold_pi``:
        the measurement is only defined modulo pi (direction of travel)."""
        residual = float(wrap_angle(theta - (self.s[2] - self.s[4] * age)))
        if fold_pi and abs(residual) > 0.5 * np.pi:
            residual = float(wrap_angle(residual + np.pi))
        self._update(np.array([[0.0, 0.0, 1.0, 0.0, -age]]), np.array([residual]), np.array([[sigma ** 2]]))

    def update_position(self, xy: np.ndarray, sigma: float) -> None:
        h = np.zeros((2, 5))
        h[0, 0] = h[1, 1] = 1.0
        self._update(h, np.asarray(xy, dtype=np.float64)[:2] - self.s[:2], np.eye(2) * sigma ** 2)


def travel_heading(displacement: np.ndarray, position_sigma: float, floor_sigma: float,
                   min_travel: float) -> tuple[float, float] | None:
    """(direction, sigma) of a BEV displacement as a heading measurement, or None when it is too short.

    sigma = floor + sqrt(2) * position_sigma / |d| (two position errors across the baseline |d|)."""
    d = np.asarray(displacement, dtype=np.float64)[:2]
    length = float(np.hypot(d[0], d[1]))
    if length < min_travel:
        return None
    return float(np.arctan2(d[1], d[0])), floor_sigma + np.sqrt(2.0) * position_sigma / length


class HeightFilter:
    """The box centre's z: a random walk (``drift_sigma`` m per frame) measured by the registration
    (``fit_sigma``) and by road height + offset (``road_sigma``), the offset averaged slowly (``offset_gain``)
    from the estimate's height above the road, or on the frames ``update`` is told so, from the registration's
    (``offset_fit_gain``: a road seen with a slowly changing bias, far out, then moves the offset, not the box)."""

    def __init__(self, z: float, road: float | None, drift_sigma: float, fit_sigma: float, road_sigma: float,
                 offset_gain: float, offset_fit_gain: float = 0.0) -> None:
        self.z = float(z)
        self.var = 0.0
        self.offset = None if road is None else float(z - road)
        self.drift_sigma, self.fit_sigma, self.road_sigma = drift_sigma, fit_sigma, road_sigma
        self.offset_gain = offset_gain
        self.offset_fit_gain = offset_fit_gain

    def _measure(self, value: float, sigma: float) -> None:
        gain = self.var / (self.var + sigma ** 2)
        self.z += gain * (value - self.z)
        self.var *= 1.0 - gain

    def update(self, fit_z: float | None, road: float | None, road_sigma: float | None = None,
               offset_from_fit: bool = False) -> float:
        """One frame: predict, then fuse the fit's z and the road prior (``road_sigma``: this frame's, else the
        filter's); the offset follows the fit's z above the road if ``offset_from_fit`` and ``offset_fit_gain`` > 0,
        else the estimate's; returns the new z."""
        self.var += self.drift_sigma ** 2
        if road is not None and self.offset is not None:
            self._measure(road + self.offset, self.road_sigma if road_sigma is None else road_sigma)
        if fit_z is not None and np.isfinite(fit_z):
            self._measure(float(fit_z), self.fit_sigma)
        if road is not None:
            if self.offset is None:
                self.offset = self.z - road
            elif not (offset_from_fit and self.offset_fit_gain > 0.0):
                self.offset += self.offset_gain * (self.z - road - self.offset)
            elif fit_z is not None and np.isfinite(fit_z):
                self.offset += self.offset_fit_gain * (float(fit_z) - road - self.offset)
        return self.z


class CTRVMotion:
    """The tracker's CTRV motion model: per-frame motion predictions [dx, dy, dz, dtheta] from a box, and the
    correction of a registered motion by the filter (heading measurements, then the centre).

    ``update`` turns the box about the centroid of its visible points to the filtered heading (the data pin the
    points, not the rotation about them) and measures the centre there.
    """

    def __init__(self, box: Box, params: CTRVParams, position_sigma: float, heading_sigma: float,
                 travel_sigma: float, travel_min_distance: float) -> None:
        self.filter = CTRVFilter(box.x, box.y, box.heading, params)
        self.position_sigma = position_sigma
        self.heading_sigma = heading_sigma
        self.travel_sigma = travel_sigma
        self.travel_min_distance = travel_min_distance

    def predict(self, box: Box, dt: float, coasting: int = 0) -> np.ndarray:
        """Advance the filter by ``dt`` seconds; the predicted motion from ``box``."""
        self.filter.predict(dt)
        s = self.filter.s
        return np.array([s[0] - box.x, s[1] - box.y, 0.0, float(wrap_angle(s[2] - box.heading))])

    def search_sigma(self) -> float:
        return self.filter.position_sigma()

    def update(self, box: Box, x: np.ndarray, previous_centroid: np.ndarray | None,
               current_centroid: np.ndarray | None, dt: float = 0.1, points: int = 0) -> np.ndarray:
        """Fuse the registered motion ``x`` (from ``box``, ``dt`` seconds ago); returns the corrected motion.
        ``points``: the object's points in the new box (unused here).

        The direction of travel over the interval is the heading at its middle (``dt / 2`` ago)."""
        x = np.asarray(x, dtype=np.float64).copy()
        fit_heading = box.heading + x[3]
        self.filter.update_heading(fit_heading, self.heading_sigma)
        if self.travel_sigma > 0 and previous_centroid is not None:
            # the visible points' displacement, less the part a turn adds to a point off the centre (the
            # filter's turn over the interval), is the centre's: along the heading at mid-interval
            moved = apply_motion(x, previous_centroid[None], box.center)[0]
            arm = previous_centroid[:2] - box.center[:2]
            c, s = np.cos(self.filter.turn_rate * dt), np.sin(self.filter.turn_rate * dt)
            swing = np.array([c * arm[0] - s * arm[1], s * arm[0] + c * arm[1]]) - arm
            travel = travel_heading(moved[:2] - previous_centroid[:2] - swing, self.position_sigma, self.travel_sigma,
                                    self.travel_min_distance)
            if travel is not None:
                self.filter.update_heading(travel[0], travel[1], fold_pi=True, age=0.5 * dt)
        turn = float(wrap_angle(self.filter.heading - fit_heading))
        centre = box.center[:2] + x[:2]
        if current_centroid is not None:
            c, s = np.cos(turn), np.sin(turn)
            arm = centre - current_centroid[:2]
            centre = current_centroid[:2] + np.array([c * arm[0] - s * arm[1], s * arm[0] + c * arm[1]])
        self.filter.update_position(centre, self.position_sigma)
        x[:2] = centre - box.center[:2]
        x[3] += turn
        return x


def _within_slip(velocity: np.ndarray, heading: float, max_slip: float, max_slide: float = 0.0) -> np.ndarray:
    """``velocity`` (xy) with its part across the ``heading`` line capped at tan(``max_slip``) x its part along it;
    with ``max_slide`` > 0 only where that part across is at most ``max_slide`` (the same units as ``velocity``)."""
    axis = np.array([np.cos(heading), np.sin(heading)])
    across_axis = np.array([-axis[1], axis[0]])
    along, across = float(velocity @ axis), float(velocity @ across_axis)
    if 0 < max_slide < abs(across):
        return velocity
    limit = abs(along) * np.tan(max_slip)
    return along * axis + float(np.clip(across, -limit, limit)) * across_axis


class AverageMotion:
    """The paper's moving-average motion prior behind the same interface.

    ``per_second``: the average is kept per second (each motion divided by its interval) and predicted for the
    elapsed time, so a gap of several frames is predicted correctly; else per frame (the paper; dt ignored).
    ``trend``: Holt's trend weight (:class:`~tracker.motion.MotionPrior`); a coasting frame is predicted on the
    average alone. ``trend_points`` (n0 > 0): the support of a motion registered on n object points is
    n / (n + n0): it adds that share of its change to the trend, and the next frame is predicted that share of
    the way from the average to the trend's prediction (a dense object's registrations pin its motion, a sparse
    or partly seen one's slide: it keeps the average's robust, lagging prediction). ``coast_max_slip`` (rad, > 0): a
    coasting frame's predicted velocity keeps its part along the box's heading and its part across is capped at
    tan(coast_max_slip) x that; with ``coast_max_slide`` (m/s, > 0) only where the part across is at most that;
    with ``coast_steady_frames`` (n > 0) only when the box's heading after each of the last n updates lay within
    ``coast_steady_max`` (rad) of the last one (a heading that swung before the loss is no line to coast along).
    """

    def __init__(self, alpha: float, frame: str, coast_yaw_decay: float, per_second: bool = False,
                 first_along_heading: bool = False, trend: float = 0.0, trend_points: int = 0,
                 trend_velocity: bool = True, first_turn_points: int = 0, first_turn_max: float = 0.0,
                 ramp: SpeedRamp | None = None, coast_max_slip: float = 0.0,
                 coast_max_slide: float = 0.0, coast_steady_frames: int = 0,
                 coast_steady_max: float = 0.05) -> None:
        self.prior = MotionPrior(alpha, frame, trend, trend_velocity)
        self.coast_max_slip = coast_max_slip
        self.coast_max_slide = coast_max_slide
        self.coast_steady_max = coast_steady_max
        self._headings: deque[float] = deque(maxlen=max(coast_steady_frames, 1))  # after the last updates
        self._steady_frames = coast_steady_frames
        self.ramp = ramp
        self.trend_points = trend_points
        self._support = 1.0  # the last update's support: the share of the trend's prediction
        self.coast_yaw_decay = coast_yaw_decay
        self.per_second = per_second
        self.first_along_heading = first_along_heading
        self.first_turn_points = first_turn_points
        self.first_turn_max = first_turn_max

    def predict(self, box: Box, dt: float, coasting: int = 0) -> np.ndarray:
        interval = dt if self.per_second else 1.0
        out = self.prior.predict(box.heading, interval, 0.0 if coasting else self._support)
        if self.ramp is not None:
            if coasting:
                self.ramp.reset()  # a run without data breaks the ramp; it is not extrapolated over a loss
            else:
                out = self._on_ramp(out, interval)
        out = out * interval
        out[3] *= self.coast_yaw_decay ** coasting  # coasting keeps the velocity, the turn rate dies out
        if coasting and self.coast_max_slip > 0 and self._heading_steady():  # near a held heading line
            out[:2] = _within_slip(out[:2], box.heading, self.coast_max_slip, self.coast_max_slide * dt)
        return out

    def search_sigma(self) -> float:
        return 0.0

    def update(self, box: Box, x: np.ndarray, previous_centroid: np.ndarray | None,
               current_centroid: np.ndarray | None, dt: float = 0.1, points: int = 0) -> np.ndarray:
        """Average the registered motion ``x`` (from ``box``, ``dt`` seconds); ``points``: the object's points in
        the new box, the support of the trend's change (``trend_points``)."""
        motion = np.asarray(x, dtype=np.float64)
        if self.first_along_heading and not self.prior.initialised:
            # the first motion seeds the prior with only its part along the start box's heading: the start box is
            # given, a vehicle moves along its heading, and a sideways part (what a face seen alone cannot pin)
            # would be predicted on as a sideways velocity
            c, s = np.cos(box.heading), np.sin(box.heading)
            along = c * motion[0] + s * motion[1]
            motion = np.array([c * along, s * along, motion[2], motion[3]])
        if self.first_turn_points > 0 and not self.prior.initialised:
            # the first heading change seeds the turn rate as far as its points pin it: the start box's heading is
            # given, and a frame-1 rotation of a few points (a partial view sliding) seeded in full is predicted on
            # as a turn, which the yaw cap (motion.max_yaw_change, against the prediction) then enforces
            motion = motion.copy()
            motion[3] *= points / (points + self.first_turn_points)
        if self.first_turn_max > 0 and not self.prior.initialised:
            motion = motion.copy()
            motion[3] = np.clip(motion[3], -self.first_turn_max, self.first_turn_max)
        self._support = points / (points + self.trend_points) if self.trend_points > 0 else 1.0
        self._headings.append(box.heading + float(x[3]))
        rate, interval = (motion / dt, dt) if self.per_second else (motion, 1.0)
        self.prior.update(rate, box.heading, interval, self._support)
        if self.ramp is not None:
            self.ramp.add(float(np.hypot(rate[0], rate[1])), interval)
        return x

    def _heading_steady(self) -> bool:
        """Whether the box's heading after each of the last ``coast_steady_frames`` updates lay within
        ``coast_steady_max`` of the last (always, with ``coast_steady_frames`` 0)."""
        if self._steady_frames <= 0:
            return True
        if len(self._headings) < self._steady_frames:
            return False
        swing = wrap_angle(np.asarray(self._headings) - self._headings[-1])
        return bool(np.max(np.abs(swing)) <= self.coast_steady_max)

    def _on_ramp(self, out: np.ndarray, interval: float) -> np.ndarray:
        """The predicted motion (per unit of interval) with its speed moved toward the speed ramp's, as far as
        the ramp is trusted; its direction stays the average's."""
        assert self.ramp is not None
        speed, weight = self.ramp.speed(interval)
        average = float(np.hypot(out[0], out[1]))
        if weight <= 0 or average < 1e-6:
            return out
        out = out.copy()
        out[:2] *= (average + weight * (speed - average)) / average
        return out
