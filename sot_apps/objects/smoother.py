"""Per-object kinematics from per-frame box states: an RTS smoother on a CTRV model.

Model (documented in docs/motion-export.md). The state of one object is

    s = [x, y, theta, v, omega, z, vz, beta]

with (x, y, z) the WORLD box centre, theta the heading of the box's length axis (kept continuous,
i.e. unwrapped), v the SIGNED speed of the centre (negative when reversing), omega the yaw rate, vz
the vertical speed and beta the side-slip angle between the heading and the centre's direction of
travel phi = theta + beta. (The centre of a turning car does not move along its length axis: it
slips by about atan(l_rear * omega / v), over 10 degrees for a slow car turning a corner. A plain
CTRV model that forces the velocity along the heading biases positions and speeds there.)
Between two frames dt apart the centre moves on a circular arc (constant turn rate and velocity,
CTRV, with a slowly varying slip):

    x' = x + v dt (cos(phi) f1(a) - sin(phi) f2(a))      a = omega dt, phi = theta + beta
    y' = y + v dt (sin(phi) f1(a) + cos(phi) f2(a))      f1(a) = sin(a)/a, f2(a) = (1 - cos(a))/a
    theta' = theta + omega dt,  v' = v,  omega' = omega,  z' = z + vz dt,  vz' = vz,  beta' = beta

(f1, f2 use their Taylor series near a = 0, so straight-line motion needs no special case).
Process noise is white longitudinal acceleration (sigma_accel), yaw acceleration
(sigma_yaw_accel), vertical acceleration (sigma_vertical_accel) and slip rate (sigma_slip_rate),
integrated over dt; the slip starts at 0 with prior sigma initial_sigma_slip. The
measurements are the box centre and heading, z = [x, y, theta, z]; the heading innovation is
wrapped to [-pi, pi), which keeps theta unwrapped across the +-pi seam.

An extended Kalman filter runs forward over the frame times (irregular steps are handled exactly:
every step uses its own dt) and a Rauch-Tung-Striebel pass runs backward. The pair is run three times,
each pass started from the previous pass's smoothed initial state, which removes the start-up
transient of the unknown initial speed and yaw rate.

Outputs per frame, as an :class:`~sot_apps.io.object_track.ObjectTrack` with its kinematics columns: the smoothed
boxes (position, heading wrapped, the input's size and tilts), velocity (x, y) = v (cos phi, sin phi),
speed = |v|, yaw rate = omega, longitudinal acceleration = dv/dt (np.gradient of the smoothed v
over the true frame times), and 1-sigma uncertainties from the smoothed covariance.

Frames whose measurement is invalid (the tracker flagged them) are not used as measurements; the
smoother predicts through them, but their outputs are NaN and ``valid`` is False — never an
interpolated value presented as data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracker import ctrv_arc, wrap_angle

from ..io.object_track import ObjectTrack

__all__ = ["SmootherConfig", "smooth_track", "ctrv_transition", "central_difference_kinematics"]

_NX = 8  # x, y, theta, v, omega, z, vz, beta
_IX, _IY, _ITH, _IV, _IW, _IZ, _IVZ, _IB = range(_NX)
_H = np.zeros((4, _NX))
_H[0, _IX] = _H[1, _IY] = _H[2, _ITH] = _H[3, _IZ] = 1.0


@dataclass(frozen=True)
class SmootherConfig:
    """Noise model of the CTRV RTS smoother (1-sigma values, SI units)."""

    sigma_position: float = 0.10        # m, measurement noise of the box centre (x, y)
    sigma_heading: float = 0.03         # rad, measurement noise of the heading
    sigma_z: float = 0.10               # m, measurement noise of the centre height
    sigma_accel: float = 3.0            # m/s^2, longitudinal acceleration (process noise)
    sigma_yaw_accel: float = 1.0        # rad/s^2, yaw acceleration (process noise)
    sigma_vertical_accel: float = 0.5   # m/s^2, vertical acceleration (process noise)
    sigma_slip_rate: float = 0.3        # rad/s, rate of change of the side-slip angle (process noise)
    initial_sigma_slip: float = 0.2     # rad, prior on the side-slip angle (mean 0)
    initial_sigma_speed: float = 10.0   # m/s, prior on the initial speed
    initial_sigma_yaw_rate: float = 1.0  # rad/s, prior on the initial yaw rate
    passes: int = 3                     # EKF+RTS passes (>= 1)

    def to_dict(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


# Presets: tracker outputs are noisier than human annotations.
TRACKER_SMOOTHER = SmootherConfig()
ANNOTATION_SMOOTHER = SmootherConfig(sigma_position=0.05, sigma_heading=0.02, sigma_z=0.05)


def ctrv_transition(state: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """CTRV prediction of a state over ``dt`` seconds (:func:`tracker.ctrv_arc` along heading + slip, z at
    constant vertical speed): (next state, Jacobian d next / d state)."""
    x, y, th, v, w, z, vz, beta = state
    (dx, dy), arc = ctrv_arc(th + beta, v, w, dt)
    out = np.array([x + dx, y + dy, th + w * dt, v, w, z + vz * dt, vz, beta])
    F = np.eye(_NX)
    F[_IX, _ITH] = F[_IX, _IB] = arc[0, 0]
    F[_IY, _ITH] = F[_IY, _IB] = arc[1, 0]
    F[_IX, _IV], F[_IY, _IV] = arc[0, 1], arc[1, 1]
    F[_IX, _IW], F[_IY, _IW] = arc[0, 2], arc[1, 2]
    F[_ITH, _IW] = dt
    F[_IZ, _IVZ] = dt
    return out, F


def _process_noise(state: np.ndarray, dt: float, cfg: SmootherConfig) -> np.ndarray:
    c, s = np.cos(state[_ITH] + state[_IB]), np.sin(state[_ITH] + state[_IB])
    G = np.zeros((_NX, 4))
    G[_IX, 0] = 0.5 * dt * dt * c
    G[_IY, 0] = 0.5 * dt * dt * s
    G[_IV, 0] = dt
    G[_ITH, 1] = 0.5 * dt * dt
    G[_IW, 1] = dt
    G[_IZ, 2] = 0.5 * dt * dt
    G[_IVZ, 2] = dt
    G[_IB, 3] = dt
    q = np.diag([cfg.sigma_accel ** 2, cfg.sigma_yaw_accel ** 2, cfg.sigma_vertical_accel ** 2,
                 cfg.sigma_slip_rate ** 2])
    return G @ q @ G.T


def _initial_state(t: np.ndarray, meas: np.ndarray, valid: np.ndarray) -> np.ndarray:
    idx = np.flatnonzero(valid)
    first = meas[idx[0]]
    v0, vz0 = 0.0, 0.0
    if len(idx) > 1:
        second = meas[idx[1]]
        dt = t[idx[1]] - t[idx[0]]
        v0 = float((second[0] - first[0]) * np.cos(first[2]) + (second[1] - first[1]) * np.sin(first[2])) / dt
        vz0 = float(second[3] - first[3]) / dt
    return np.array([first[0], first[1], first[2], v0, 0.0, first[3], vz0, 0.0])


def _ekf_rts(t: np.ndarray, meas: np.ndarray, valid: np.ndarray, r_scale: np.ndarray,
             s0: np.ndarray, p0: np.ndarray, cfg: SmootherConfig) -> tuple[np.ndarray, np.ndarray]:
    n = len(t)
    R0 = np.diag([cfg.sigma_position ** 2, cfg.sigma_position ** 2, cfg.sigma_heading ** 2, cfg.sigma_z ** 2])
    xs_f = np.zeros((n, _NX))
    ps_f = np.zeros((n, _NX, _NX))
    xs_p = np.zeros((n, _NX))
    ps_p = np.zeros((n, _NX, _NX))
    jac = np.zeros((n, _NX, _NX))
    x, P = s0.copy(), p0.copy()
    for k in range(n):
        if k > 0:
            dt = t[k] - t[k - 1]
            x_new, F = ctrv_transition(x, dt)
            P = F @ P @ F.T + _process_noise(x, dt, cfg)
            x = x_new
            jac[k] = F
        xs_p[k], ps_p[k] = x, P
        if valid[k]:
            innovation = meas[k] - _H @ x
            innovation[2] = wrap_angle(innovation[2])
            S = _H @ P @ _H.T + R0 * r_scale[k] ** 2
            K = np.linalg.solve(S, _H @ P).T  # P H^T S^-1 (S, P symmetric)
            x = x + K @ innovation
            I_KH = np.eye(_NX) - K @ _H
            P = I_KH @ P @ I_KH.T + K @ (R0 * r_scale[k] ** 2) @ K.T  # Joseph form
        xs_f[k], ps_f[k] = x, P
    xs_s, ps_s = xs_f.copy(), ps_f.copy()
    for k in range(n - 2, -1, -1):
        F = jac[k + 1]
        C = np.linalg.solve(ps_p[k + 1], F @ ps_f[k]).T  # P_f F^T P_p^-1
        xs_s[k] = xs_f[k] + C @ (xs_s[k + 1] - xs_p[k + 1])
        ps_s[k] = ps_f[k] + C @ (ps_s[k + 1] - ps_p[k + 1]) @ C.T
        ps_s[k] = 0.5 * (ps_s[k] + ps_s[k].T)
    return xs_s, ps_s


def _kinematics(track: ObjectTrack, columns: dict[str, np.ndarray], config: dict,
                shape_points: np.ndarray | None = None) -> ObjectTrack:
    """``track``'s frames with the kinematics ``columns`` (x, y, z, heading, velocity_x, velocity_y and
    :data:`~sot_apps.io.object_track.KINEMATICS` but velocity): the boxes of the given positions and headings with
    the track's size and, at its valid frames, its [roll, pitch] (NaN elsewhere)."""
    valid = track.valid.copy()
    states = np.stack([columns.pop(name) for name in ("x", "y", "z", "heading")], axis=1)
    tilts = None if track.tilts is None else np.where(valid[:, None], track.tilts, np.nan)
    velocity = np.stack([columns.pop("velocity_x"), columns.pop("velocity_y")], axis=1)
    return ObjectTrack.from_states(track.object_id, track.label, track.size, track.frames.copy(),
                                   track.timestamps_ns.copy(), states, valid, track.flags, tilts=tilts,
                                   velocity=velocity, source=track.source, config=config, shape_points=shape_points,
                                   **columns)


def smooth_track(track: ObjectTrack, config: SmootherConfig = TRACKER_SMOOTHER,
                 measurement_sigma_scale: np.ndarray | None = None) -> ObjectTrack:
    """Smoothed kinematics of ``track`` at its frame times (see the module docstring): an ObjectTrack of the
    smoothed boxes with the kinematics columns, its shape points and its config plus ``config["smoother"]``."""
    n = len(track.frames)
    nan = np.full(n, np.nan)
    out = {name: nan.copy() for name in ("x", "y", "z", "heading", "velocity_x", "velocity_y", "speed",
                                          "acceleration", "yaw_rate", "position_std", "heading_std",
                                          "speed_std", "yaw_rate_std")}
    valid = track.valid.copy()
    idx = np.flatnonzero(valid)
    if len(idx) > 0:
        lo, hi = idx[0], idx[-1] + 1
        t = (track.timestamps_ns[lo:hi] - track.timestamps_ns[lo]).astype(np.float64) * 1e-9
        st = track.states[lo:hi]
        meas = np.stack([st[:, 0], st[:, 1], st[:, 3], st[:, 2]], axis=1)
        v = valid[lo:hi]
        meas[~v] = 0.0
        # unwrap the measured headings over the valid frames so the initial theta is continuous
        scale = np.ones(hi - lo) if measurement_sigma_scale is None else np.asarray(measurement_sigma_scale)[lo:hi]
        s0 = _initial_state(t, meas, v)
        p0 = np.diag([config.sigma_position ** 2, config.sigma_position ** 2, config.sigma_heading ** 2,
                      config.initial_sigma_speed ** 2, config.initial_sigma_yaw_rate ** 2,
                      config.sigma_z ** 2, 1.0, config.initial_sigma_slip ** 2])
        for _ in range(max(1, config.passes)):
            xs, ps = _ekf_rts(t, meas, v, scale, s0, p0, config)
            s0 = xs[0].copy()
            # keep the prior on speed / yaw rate loose but centred on the smoothed estimate
        th, sv, w = xs[:, _ITH], xs[:, _IV], xs[:, _IW]
        course = th + xs[:, _IB]
        acc = np.gradient(sv, t) if len(t) > 1 else np.zeros(1)
        block = {
            "x": xs[:, _IX], "y": xs[:, _IY], "z": xs[:, _IZ], "heading": wrap_angle(th),
            "velocity_x": sv * np.cos(course), "velocity_y": sv * np.sin(course), "speed": np.abs(sv),
            "acceleration": acc, "yaw_rate": w,
            "position_std": np.sqrt(ps[:, _IX, _IX] + ps[:, _IY, _IY]),
            "heading_std": np.sqrt(ps[:, _ITH, _ITH]), "speed_std": np.sqrt(ps[:, _IV, _IV]),
            "yaw_rate_std": np.sqrt(ps[:, _IW, _IW]),
        }
        for name, values in block.items():
            arr = out[name]
            arr[lo:hi] = np.atleast_1d(values)
            arr[~valid] = np.nan
    return _kinematics(track, out, {**track.config, "smoother": {"model": "CTRV EKF + RTS", **config.to_dict()}},
                       track.shape_points)


def central_difference_kinematics(track: ObjectTrack) -> ObjectTrack:
    """Unsmoothed reference: velocity and yaw rate by central differences of the raw states
    (one-sided at the ends and next to invalid frames; np.gradient over the true frame times).

    Used as an independent reference for ground-truth boxes. Samples whose neighbours are invalid
    use the available one-sided difference; a sample without a valid neighbour gets NaN.
    """
    n = len(track.frames)
    t = track.timestamps_ns.astype(np.float64) * 1e-9
    st = track.states
    valid = track.valid
    vx, vy, w = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    heading = np.unwrap(np.where(valid, st[:, 3], 0.0)) if n else st[:, 3]
    # work on runs of consecutive valid frames
    runs = np.split(np.arange(n), np.flatnonzero(np.diff(valid.astype(int)) != 0) + 1) if n else []
    for run in runs:
        if len(run) < 2 or not valid[run[0]]:
            continue
        tr = t[run]
        vx[run] = np.gradient(st[run, 0], tr)
        vy[run] = np.gradient(st[run, 1], tr)
        w[run] = np.gradient(np.unwrap(st[run, 3]), tr)
    speed = np.hypot(vx, vy)
    c, s = np.cos(heading), np.sin(heading)
    acc = np.full(n, np.nan)
    for run in runs:
        if len(run) < 2 or not valid[run[0]]:
            continue
        acc[run] = np.gradient(vx[run] * c[run] + vy[run] * s[run], t[run])
    nan = np.full(n, np.nan)
    mask = lambda a: np.where(valid, a, np.nan)  # noqa: E731
    return _kinematics(track, {"x": mask(st[:, 0]), "y": mask(st[:, 1]), "z": mask(st[:, 2]),
                               "heading": mask(wrap_angle(st[:, 3])), "velocity_x": vx, "velocity_y": vy, "speed": speed,
                               "acceleration": acc, "yaw_rate": w, "position_std": nan.copy(), "heading_std": nan.copy(),
                               "speed_std": nan.copy(), "yaw_rate_std": nan.copy()},
                       {"smoother": {"model": "central differences"}})
