"""Realism switches applied to raw ray hits: range noise, ray drop, intensity.

Every effect is off unless switched on in :class:`Realism`, and all randomness comes from counter-based draws
(:func:`ray_draws`): ray ``i`` of a sweep has one number per effect, a function of ``Realism.seed``, the effect
and ``i`` only, so a scan is reproducible and the same seed drops the same rays whatever the scene.

- Range noise: ``r += N(0, sigma)`` with the sensor's ``range_noise_sigma``.
- Random drop: each return is lost with probability ``drop_random``.
- Grazing drop: a return whose incidence angle ``theta`` (between the reversed ray and the surface
  normal) exceeds ``grazing_start_deg`` is lost with probability
  ``((theta - start) / (90 - start)) ** 2`` (certain at 90 degrees).
- Range drop (the sensor's, e.g. ``pandaset_pandar64``): a return at range ``r`` is lost with probability
  ``clip(drop_at_zero_range + drop_per_m * r, 0, 1)`` (:meth:`Sensor.range_drop_probability`): weak far
  returns (dark paint, windows at a slant) fall below the detection threshold.
- Intensity: Lambertian times reflectivity with atmospheric range falloff,
  ``I = rho * cos(theta) * exp(-2 * attenuation * r)``, in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Realism", "incidence_cosine", "grazing_drop_probability", "lambertian_intensity", "ray_draws", "ndtri",
           "NOISE", "RANDOM_DROP", "GRAZING_DROP", "RANGE_DROP"]


@dataclass(frozen=True)
class Realism:
    """Which effects to simulate (defaults: all on except random drop; ``Realism.ideal()`` is all off)."""

    range_noise: bool = True
    drop_random: float = 0.0
    drop_grazing: bool = True
    grazing_start_deg: float = 75.0
    drop_range: bool = True
    intensity: bool = True
    attenuation_per_m: float = 0.002
    motion_distortion: bool = True
    seed: int = 0

    @classmethod
    def ideal(cls, seed: int = 0) -> "Realism":
        return cls(range_noise=False, drop_random=0.0, drop_grazing=False, drop_range=False, intensity=False,
                   motion_distortion=False, seed=seed)


def incidence_cosine(directions: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """cos(theta) between the reversed unit ray and the unit normal (normals face the origin)."""
    dot = directions[:, 0] * normals[:, 0] + directions[:, 1] * normals[:, 1] + directions[:, 2] * normals[:, 2]
    return np.clip(-dot, 0.0, 1.0)


def grazing_drop_probability(cos_incidence: np.ndarray, start_deg: float) -> np.ndarray:
    """((theta - start) / (90 - start))^2, clipped to [0, 1], for incidence angles theta beyond ``start_deg``."""
    # only grazing returns (incidence beyond the start angle) can drop: arccos just for those
    grazing = np.flatnonzero(cos_incidence < np.cos(np.radians(start_deg)))
    p = np.zeros(len(cos_incidence))
    theta = np.degrees(np.arccos(cos_incidence[grazing]))
    p[grazing] = np.clip((theta - start_deg) / max(90.0 - start_deg, 1e-6), 0.0, 1.0) ** 2
    return p


def lambertian_intensity(cos_incidence: np.ndarray, reflectivity: np.ndarray, distance: np.ndarray,
                         attenuation_per_m: float) -> np.ndarray:
    return np.clip(reflectivity * cos_incidence * np.exp(-2.0 * attenuation_per_m * distance), 0.0, 1.0)


# the draw streams, one per effect
NOISE, RANDOM_DROP, GRAZING_DROP, RANGE_DROP = 1, 2, 3, 4

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MASK64 = (1 << 64) - 1


def _mix64(z: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser on uint64 (wrapping arithmetic), in place."""
    z ^= z >> np.uint64(30)
    z *= np.uint64(0xBF58476D1CE4E5B9)
    z ^= z >> np.uint64(27)
    z *= np.uint64(0x94D049BB133111EB)
    z ^= z >> np.uint64(31)
    return z


def _mix64_int(z: int) -> int:
    z &= _MASK64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return z ^ (z >> 31)


def ray_draws(seed: int, stream: int, index: np.ndarray, normal: bool = False) -> np.ndarray:
    """The random number of rays ``index`` in ``stream`` (:data:`NOISE`, :data:`RANDOM_DROP`, :data:`GRAZING_DROP`,
    :data:`RANGE_DROP`) for ``seed``: a uniform in (0, 1), or a standard normal (``ndtri`` of it).

    ``u = ((mix64(key + (i + 1) * golden) >> 11) + 0.5) * 2**-53`` with ``key = mix64(mix64(seed) + stream)``: the
    ``i``-th output of SplitMix64 started at ``key``. The compiled loop (``sot_rt_returns``) draws the same numbers.
    """
    key = np.uint64(_mix64_int(_mix64_int(int(seed)) + int(stream)))
    z = np.asarray(index, dtype=np.int64).astype(np.uint64) + np.uint64(1)
    z *= _GOLDEN
    z += key
    u = ((_mix64(z) >> np.uint64(11)).astype(np.float64) + 0.5) * 2.0 ** -53
    return ndtri(u) if normal else u


def ndtri(p: np.ndarray) -> np.ndarray:
    """The standard normal quantile of p in (0, 1): Wichura's AS241 (PPND16, ~1e-16 relative), step for step as
    the compiled loop and CPython's ``statistics.NormalDist.inv_cdf``."""
    p = np.asarray(p, dtype=np.float64)
    q = p - 0.5
    out = np.empty_like(p)
    central = np.abs(q) <= 0.425
    qc = q[central]
    r = 0.180625 - qc * qc
    num = (((((((2.5090809287301226727e+3 * r + 3.3430575583588128105e+4) * r + 6.7265770927008700853e+4) * r
                + 4.5921953931549871457e+4) * r + 1.3731693765509461125e+4) * r + 1.9715909503065514427e+3) * r
            + 1.3314166789178437745e+2) * r + 3.3871328727963666080e+0) * qc
    den = (((((((5.2264952788528545610e+3 * r + 2.8729085735721942674e+4) * r + 3.9307895800092710610e+4) * r
                + 2.1213794301586595867e+4) * r + 5.3941960214247511077e+3) * r + 6.8718700749205790830e+2) * r
            + 4.2313330701600911252e+1) * r + 1.0)
    out[central] = num / den
    tail = np.flatnonzero(~central)
    qt = q[tail]
    r = np.sqrt(-np.log(np.where(qt <= 0.0, p[tail], 1.0 - p[tail])))
    near = r <= 5.0
    x = np.empty_like(r)
    r1 = r[near] - 1.6
    x[near] = ((((((((7.74545014278341407640e-4 * r1 + 2.27238449892691845833e-2) * r1 + 2.41780725177450611770e-1)
                    * r1 + 1.27045825245236838258e+0) * r1 + 3.64784832476320460504e+0) * r1
                  + 5.76949722146069140550e+0) * r1 + 4.63033784615654529590e+0) * r1 + 1.42343711074968357734e+0)
               / (((((((1.05075007164441684324e-9 * r1 + 5.47593808499534494600e-4) * r1 + 1.51986665636164571966e-2)
                      * r1 + 1.48103976427480074590e-1) * r1 + 6.89767334985100004550e-1) * r1
                    + 1.67638483018380384940e+0) * r1 + 2.05319162663775882187e+0) * r1 + 1.0))
    r5 = r[~near] - 5.0
    x[~near] = ((((((((2.01033439929228813265e-7 * r5 + 2.71155556874348757815e-5) * r5 + 1.24266094738807843860e-3)
                     * r5 + 2.65321895265761230930e-2) * r5 + 2.96560571828504891230e-1) * r5
                   + 1.78482653991729133580e+0) * r5 + 5.46378491116411436990e+0) * r5 + 6.65790464350110377720e+0)
                / (((((((2.04426310338993978564e-15 * r5 + 1.42151175831644588870e-7) * r5 + 1.84631831751005468180e-5)
                       * r5 + 7.86869131145613259100e-4) * r5 + 1.48753612908506148525e-2) * r5
                     + 1.36929880922735805310e-1) * r5 + 5.99832206555887937690e-1) * r5 + 1.0))
    out[tail] = np.where(qt < 0.0, -x, x)
    return out
