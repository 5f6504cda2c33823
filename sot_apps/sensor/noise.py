"""Realism switches applied to raw ray hits: range noise, ray drop, intensity.

Every effect is off unless switched on in :class:`Realism`, and all randomness comes from one seeded
``numpy.random.Generator`` so a scan is reproducible.

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

__all__ = ["Realism", "incidence_cosine", "apply_range_noise", "drop_mask", "grazing_drop_probability",
           "lambertian_intensity"]


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


def apply_range_noise(distance: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    return distance + rng.normal(0.0, sigma, size=distance.shape)


def drop_mask(cos_incidence: np.ndarray, realism: Realism, rng: np.random.Generator, num_rays: int | None = None,
              index: np.ndarray | None = None, range_drop: np.ndarray | None = None) -> np.ndarray:
    """Boolean mask of returns that are dropped.

    ``cos_incidence`` may cover a subset of the sweep: ``index`` (into ``num_rays`` rays) says which. The
    random draws always cover all ``num_rays``, so the same seed drops the same rays whatever the subset.
    ``range_drop``: per-return drop probability from the sensor's range model (None: no range drop; its draws
    come last, so sensors without one give the same scans as before).
    """
    n = cos_incidence.shape[0] if num_rays is None else int(num_rays)

    def draw() -> np.ndarray:  # one uniform per ray of the sweep, then the subset's
        u = rng.random(n)
        return u if index is None else u[index]

    u = draw()
    dropped = np.zeros(len(cos_incidence), dtype=bool)
    if realism.drop_random > 0:
        dropped |= u < realism.drop_random
    if realism.drop_grazing:
        dropped |= draw() < grazing_drop_probability(cos_incidence, realism.grazing_start_deg)
    if range_drop is not None:
        dropped |= draw() < range_drop
    return dropped


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
