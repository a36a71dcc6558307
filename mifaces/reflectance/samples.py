"""Reflectance samples: radiance turned into reflectance, with confidence
(paper sec. 4.3 and 5.1).

A reflectance sample (eq. 5) is ((l̂, v̂), r, σ): unit light and view
directions in the local shading frame, the reflectance r (RGB) and the
confidence scale σ (the fit weights a sample by 1/σ²).

**Eq. 4, the reading implemented.** The paper prints
r = R / (|l̂·n| ‖l‖²), dividing by the squared light distance. A point light
of intensity I at distance d gives the irradiance E = I cos θl / d², and the
BRDF is f = R / E, so the physical relation multiplies by d²:

    r = s · R · d² / (I · cos θl),

which is what :func:`reflectance` computes. The scale s makes a white
Lambertian target (f = 1/π) have r = 1, as the paper requires: s = π when
R and I are in consistent physical units, or the value the capture's white
target calibration gives. So r = π f for every model, and the fitters
compare r with π f(l̂, v̂).

Here are the sample's formulas (eq. 4, 9, 10), the masks that drop unusable
ones and :class:`ReflectanceSamples`, the value that holds them;
:mod:`mifaces.reflectance.resampling` takes them from the photographs.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.ndimage
import skimage.morphology

from ..io.atomic import atomic_path

#: Samples seen or lit at cos θ below this are dropped (θ > 80°).
MIN_COSINE = np.cos(np.radians(80.0))
#: Eq. 10's d_max at the paper's texture resolution of 1000².
D_MAX_AT_1000 = 10.0


def reflectance(radiance, light_distance, intensity, cos_light, scale: float = np.pi):
    """r = scale · R · d² / (I cos θl), the physical reading of eq. 4.

    Parameters
    ----------
    radiance : array (..., 3)
        Observed radiance R.
    light_distance : array (...)
        Distance d from the surface point to the light; ``inf`` for a
        directional light, whose ``intensity`` is then the irradiance E at
        normal incidence (r = scale · R / (E cos θl)).
    intensity : array (3,) or (..., 3)
        Radiant intensity I of the point light (irradiance E of a directional one).
    cos_light : array (...)
        cos θl = l̂ · n (> 0 where used; other samples are invalid).
    scale : float
        π for physical units (a white Lambertian target gives 1).

    Returns
    -------
    ndarray (..., 3)
        Reflectance; NaN where cos θl <= 0.
    """
    radiance = np.asarray(radiance, np.float64)
    d = np.asarray(light_distance, np.float64)
    d2 = np.where(np.isinf(d), 1.0, np.square(d))[..., None]  # a directional light does not fall off
    cos_light = np.asarray(cos_light, np.float64)[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = scale * radiance * d2 / (np.asarray(intensity, np.float64) * cos_light)
    return np.where(cos_light > 0, r, np.nan)


def confidence(light_z, view_z):
    """σ = 1 / (l_z² v_z), eq. 9 (l_z = cos θl, v_z = cos θv, both > 0)."""
    light_z, view_z = np.asarray(light_z, np.float64), np.asarray(view_z, np.float64)
    return 1.0 / (np.square(light_z) * view_z)


def d_max(resolution: int) -> float:
    """Eq. 10's d_max in texels at texture resolution ``resolution``: the
    paper's 10 texels at 1000², scaled with the resolution."""
    return D_MAX_AT_1000 * resolution / 1000.0


def distance_to_missing(valid: np.ndarray) -> np.ndarray:
    """Euclidean distance in texels from each valid texel to the nearest
    texel without a sample (0 on invalid texels). Texels outside the image
    count as missing."""
    valid = np.asarray(valid, bool)
    padded = np.pad(valid, 1, constant_values=False)
    return scipy.ndimage.distance_transform_edt(padded)[1:-1, 1:-1]


def confidence_with_distance(light_z, view_z, distance, dmax):
    """σ = d_max / (min(d, d_max) · l_z² · v_z), eq. 10."""
    distance = np.asarray(distance, np.float64)
    with np.errstate(divide="ignore"):
        return dmax / (np.minimum(distance, dmax) * np.square(light_z) * np.asarray(view_z, np.float64))


def unsaturated(pixels, saturation: float = 1.0, margin: float = 0.98):
    """Pixels whose every channel stays below ``margin · saturation``: a
    clipped channel no longer measures the radiance, so its sample is
    dropped rather than fitted. ``pixels`` is (..., 3) in the camera's
    linear units, ``saturation`` the level at which the sensor clips."""
    return np.all(np.asarray(pixels) < margin * saturation, axis=-1)


def valid_samples(light_z, view_z, lit, visible, erosion: int = 1, min_cosine: float = MIN_COSINE):
    """Texels that give a usable sample (sec. 4.3).

    A texel is kept where it is visible from the camera, not in cast shadow,
    and neither seen nor lit at a grazing angle (cos θ >= ``min_cosine``);
    the mask is then eroded by ``erosion`` texels so that samples along
    shadow borders and occluding contours are dropped too.

    Parameters
    ----------
    light_z, view_z : ndarray (R, R)
        cos θl and cos θv per texel.
    lit, visible : ndarray (R, R) of bool
        Not in cast shadow; seen by the camera.
    """
    light_z, view_z = np.asarray(light_z), np.asarray(view_z)
    with np.errstate(invalid="ignore"):
        mask = np.asarray(lit, bool) & np.asarray(visible, bool) & (light_z >= min_cosine) & (view_z >= min_cosine)
    if erosion > 0:
        mask = skimage.morphology.erosion(mask, skimage.morphology.disk(erosion))
    return mask


# ---------------------------------------------------------------------------
# The samples, in the common texture parameterization (sec. 4.3;
# :mod:`mifaces.reflectance.resampling` takes them from the photographs)

@dataclass
class ReflectanceSamples:
    """Reflectance samples of one or more measurements, in texture space.

    Attributes
    ----------
    light, view : (N, 3) float32
        l̂ and v̂ in the local shading frame (tangent along +u, normal z).
    reflectance : (N, 3) float32
        r, 1 for a white Lambertian target (r = π f).
    sigma : (N,) float32
        Confidence of eq. 10 (weights are 1/σ²).
    texel : (N,) int32
        Flat texel index row · R + column.
    measurement : (N,) int16
        Index into ``measurement_names``.
    resolution : int
        R of the R × R texture.
    measurement_names : tuple of str
    label : (N,) uint8 or None
        Region label of each sample (:data:`mifaces.model.regions.REGIONS`),
        from the face model's a-priori region map (sec. 4.4).
    region_map : (R, R) uint8 or None
        That region map: the region of every texel, as the rendered face
        assigns materials (computed once, with the samples).
    footprint : (N, 3) float32 or None
        The covariance of the normal's tilt over each sample's pixel (tt, tb, bb, radians², along
        the local tangent and bitangent; :func:`mifaces.reflectance.footprint.normal_spread`): the
        fit averages the model over it. None: point samples.
    """

    light: np.ndarray
    view: np.ndarray
    reflectance: np.ndarray
    sigma: np.ndarray
    texel: np.ndarray
    measurement: np.ndarray
    resolution: int
    measurement_names: tuple = ()
    label: np.ndarray | None = None
    region_map: np.ndarray | None = None
    footprint: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.sigma)

    def labels(self) -> np.ndarray:
        """Each sample's region label (:attr:`label`); a ``ValueError`` for samples that have none."""
        if self.label is None:
            raise ValueError("the samples have no region labels (samples.label; ReflectanceSamples.region)")
        return np.asarray(self.label)

    def select(self, mask) -> ReflectanceSamples:
        """The samples ``mask`` selects, as a new set.

        Parameters
        ----------
        mask : ndarray (N,) of bool, or of indices
            Which samples to keep.

        Returns
        -------
        ReflectanceSamples
            Every per-sample array (``light``, ``view``, ``reflectance``, ``sigma``, ``texel``,
            ``measurement``, and ``label`` and ``footprint`` where present) indexed by ``mask``;
            ``resolution``, ``measurement_names`` and ``region_map`` kept.
        """
        return replace(self, light=self.light[mask], view=self.view[mask], reflectance=self.reflectance[mask],
                       sigma=self.sigma[mask], texel=self.texel[mask], measurement=self.measurement[mask],
                       label=None if self.label is None else self.label[mask],
                       footprint=None if self.footprint is None else self.footprint[mask])

    def region(self, region_map: np.ndarray) -> np.ndarray:
        """Region label of each sample from an (R, R) region map."""
        if region_map.shape != (self.resolution, self.resolution):
            raise ValueError(f"region map of shape {region_map.shape} does not match the samples' "
                             f"{self.resolution}x{self.resolution} texture")
        return region_map.ravel()[self.texel]

    @staticmethod
    def concatenate(parts: list[ReflectanceSamples]) -> ReflectanceSamples:
        """One set from several (same resolution); measurement indices follow
        the order of ``parts``."""
        if not parts:
            raise ValueError("no reflectance samples to concatenate")
        if len({p.resolution for p in parts}) != 1:
            raise ValueError("reflectance samples of different texture resolutions cannot be combined")
        names, offsets = [], []
        for p in parts:
            offsets.append(len(names))
            names += list(p.measurement_names)
        labelled = all(p.label is not None for p in parts)
        footprints = all(p.footprint is not None for p in parts)
        return ReflectanceSamples(
            *(np.concatenate([getattr(p, k) for p in parts]) for k in ("light", "view", "reflectance", "sigma", "texel")),
            measurement=np.concatenate([p.measurement + o for p, o in zip(parts, offsets)]).astype(np.int16),
            resolution=parts[0].resolution, measurement_names=tuple(names),
            label=np.concatenate([p.label for p in parts]) if labelled else None,
            region_map=parts[0].region_map,
            footprint=np.concatenate([p.footprint for p in parts]) if footprints else None)

    def save(self, path) -> None:
        """Write as a compressed ``.npz``, atomically."""
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(f, light=self.light, view=self.view, reflectance=self.reflectance,
                                    sigma=self.sigma, texel=self.texel, measurement=self.measurement,
                                    resolution=self.resolution, measurement_names=np.array(self.measurement_names),
                                    **({} if self.label is None else {"label": self.label}),
                                    **({} if self.footprint is None else {"footprint": self.footprint}))

    @staticmethod
    def load(path) -> ReflectanceSamples:
        with np.load(path) as d:
            return ReflectanceSamples(d["light"], d["view"], d["reflectance"], d["sigma"], d["texel"],
                                      d["measurement"], int(d["resolution"]),
                                      tuple(str(n) for n in d["measurement_names"]),
                                      d["label"] if "label" in d.files else None,
                                      footprint=d["footprint"] if "footprint" in d.files else None)


__all__ = ["MIN_COSINE", "D_MAX_AT_1000", "reflectance", "confidence", "d_max", "distance_to_missing",
           "confidence_with_distance", "unsaturated", "valid_samples", "ReflectanceSamples"]
