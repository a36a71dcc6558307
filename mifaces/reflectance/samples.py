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
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import drjit as dr
import mitsuba as mi
import numpy as np
import scipy.ndimage
import skimage.morphology

from ..io.atomic import atomic_path
from ..model.mesh import mitsuba_mesh
from ..runtime.progress import progress as progress_bar
from .environment import LUMINANCE, equivalent_lights
from .footprint import normal_spread
from .mixed_pixels import region_mixed
from ..model.regions import texel_regions_of_mesh
from ..model.texture_space import rasterize, texel_geometry

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
# Resampling a photograph into the common texture parameterization (sec. 4.3)

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


def _unoccluded(scene, origin, target, normal, offset: float) -> np.ndarray:
    """True where the segment from ``origin`` (pushed ``offset`` along the
    normal) to ``target`` hits nothing in ``scene``."""
    if len(origin) == 0:
        return np.zeros(0, bool)
    start = origin + offset * normal
    d = target - start
    dist = np.linalg.norm(d, axis=1)
    d = d / np.maximum(dist, 1e-30)[:, None]
    ray = mi.Ray3f(mi.Point3f(start.T.astype(np.float32)), mi.Vector3f(d.T.astype(np.float32)))
    ray.maxt = mi.Float((dist * (1 - 1e-4)).astype(np.float32))
    hit = scene.ray_test(ray)
    return ~np.array(hit, dtype=bool) if dr.is_jit_v(mi.Float) else np.array([not hit])


def read_photograph(camera, pixels, saturated, points) -> tuple[np.ndarray, np.ndarray]:
    """The photograph ``pixels`` (H, W, 3) at the projections of world ``points`` (N, 3): bilinear,
    pixel centres at integers; (N, 3) radiance, and (N,) whether the point projects inside the
    image and away from ``saturated`` pixels ((H, W) bool or None; dilated by one pixel, since
    the bilinear taps touch the neighbours)."""
    xy = camera.project(points)
    ok = (xy[:, 0] >= 0) & (xy[:, 0] <= camera.width - 1) & (xy[:, 1] >= 0) & (xy[:, 1] <= camera.height - 1)
    coords = [xy[:, 1], xy[:, 0]]
    pixels = np.asarray(pixels, np.float32)
    radiance = np.stack([scipy.ndimage.map_coordinates(pixels[..., c], coords, order=1, mode="nearest")
                         for c in range(3)], axis=1)
    if saturated is not None:
        near = scipy.ndimage.binary_dilation(np.asarray(saturated, bool))
        ok &= ~scipy.ndimage.map_coordinates(near.astype(np.uint8), coords, order=0, mode="nearest").astype(bool)
    return radiance, ok


def measurement_samples(camera, light, pixels, vertices, triangles, uv, raster, *, saturated=None,
                        scale: float = np.pi, erosion: int = 1, min_cosine: float = MIN_COSINE, name: str = "",
                        offset: float | None = None, indirect=None, regions=None) -> ReflectanceSamples:
    """Reflectance samples of one photograph (paper sec. 4.3, 5.3).

    Parameters
    ----------
    camera : mifaces.capture.Camera
        Calibrated camera (world frame in mm, OpenCV pixel conventions).
    light : mifaces.capture.Light
        The photograph's light: a point light (``position``, world frame, mm; ``intensity``,
        its radiant intensity in the units of ``pixels``·mm²), a directional one (``direction``,
        the unit vector in the world frame towards the light; ``intensity``, its irradiance in the
        units of ``pixels``) or an environment map (``envmap``, (H, 2H, 3): each texel is read as
        lit by the directional light that stands for the map there,
        :func:`mifaces.reflectance.environment.equivalent_lights`).
    pixels : (H, W, 3) linear radiance image.
    vertices : (V, 3) the face in world coordinates for this measurement.
    triangles, uv : the model's triangles and texture coordinates.
    raster : :class:`mifaces.model.texture_space.TextureRaster` of ``uv`` at R × R.
    saturated : (H, W) bool, optional; saturated pixels give no sample.
    scale : float
        Scale of eq. 4 (π: a white Lambertian target has r = 1).
    erosion : int
        Texels eroded from the borders of the valid region.
    indirect : (H, W, 3) array, optional
        Light bounced off the face, units of ``pixels`` (:mod:`mifaces.reflectance.interreflection`): subtracted.
    regions : (R, R) int array, optional
        Region label of every texel: no sample from a texel that reads another region's pixels (:func:`region_mixed`).

    Returns
    -------
    ReflectanceSamples
        Valid texels only (seen, lit, not grazing, in the image, unsaturated, unmixed); σ by eq. 10.
    """
    pixels = np.asarray(pixels, np.float32)
    if pixels.shape != (camera.height, camera.width, 3):
        raise ValueError(f"image of shape {pixels.shape} does not match the camera's "
                         f"{camera.height}x{camera.width}x3")
    if not np.all(np.isfinite(pixels)):
        raise ValueError(f"image contains {np.count_nonzero(~np.isfinite(pixels))} NaN or infinite values")
    resolution = raster.triangle.shape[0]
    geo = texel_geometry(vertices, triangles, uv, raster)
    p, n = geo.position, geo.normal
    size = float(np.ptp(np.asarray(vertices), axis=0).max())
    offset = 1e-4 * size if offset is None else offset
    scene = mi.load_dict({"type": "scene", "face": mitsuba_mesh(vertices, triangles, uv)})
    to_camera = camera.position[None, :] - p
    envmap, light_direction, intensity = light.envmap, light.direction, light.intensity
    if envmap is not None:  # per texel the directional light that stands for the map
        l_world, e = equivalent_lights(scene, p, n, envmap, camera, offset, 10.0 * size)
        dist_light = np.full(len(p), np.inf)
        light_target = None
    elif light_direction is not None:  # a distant light: one direction, no falloff
        l_world = np.broadcast_to(np.asarray(light_direction, np.float64) /
                                  np.linalg.norm(light_direction), p.shape).copy()
        dist_light = np.full(len(p), np.inf)
        light_target = p + l_world * (10.0 * size)  # far beyond the face: shadow rays leave it
    else:
        to_light = np.asarray(light.position, np.float64)[None, :] - p
        dist_light = np.linalg.norm(to_light, axis=1)
        l_world = to_light / dist_light[:, None]
        light_target = np.broadcast_to(np.asarray(light.position, np.float64), p.shape)
    v_world = to_camera / np.linalg.norm(to_camera, axis=1, keepdims=True)
    cos_l, cos_v = np.sum(l_world * n, 1), np.sum(v_world * n, 1)
    front = (cos_l > 0) & (cos_v > 0)
    visible, lit = np.zeros(len(p), bool), np.zeros(len(p), bool)
    visible[front] = _unoccluded(scene, p[front], np.broadcast_to(camera.position, p[front].shape), n[front], offset)
    if light_target is None:  # the map's light arrives unoccluded along its irradiance vector, by construction
        lit[front] = (e[front] @ LUMINANCE) > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            intensity = e / np.where(cos_l > 0, cos_l, np.nan)[:, None]  # irradiance at normal incidence
    else:
        lit[front] = _unoccluded(scene, p[front], light_target[front], n[front], offset)
    radiance, ok = read_photograph(camera, pixels, saturated, p)
    if indirect is not None:  # the bounced light out: eq. 4 reads direct light
        if np.shape(indirect) != pixels.shape:
            raise ValueError(f"bounced light of shape {np.shape(indirect)} does not match the image's {pixels.shape}")
        radiance = radiance - read_photograph(camera, indirect, None, p)[0]
    r = reflectance(radiance, dist_light, intensity, cos_l, scale)

    def image(values, fill):
        out = np.full(resolution * resolution, fill, dtype=np.asarray(values).dtype)
        out[geo.texel] = values
        return out.reshape(resolution, resolution)

    valid = valid_samples(image(cos_l, 0.0), image(cos_v, 0.0), image(lit & ok, False),
                          image(visible & np.all(np.isfinite(r), axis=1), False), erosion, min_cosine)
    xy = camera.project(p)
    if regions is not None:  # after the erosion: a region border is no hole in the valid region
        mixed = region_mixed(xy, np.ravel(regions)[geo.texel], visible & ok, pixels.shape[:2])
        valid &= ~image(mixed, False)
    keep = valid.ravel()[geo.texel]
    distance = distance_to_missing(valid).ravel()[geo.texel[keep]]
    frame = np.stack([geo.tangent[keep], geo.bitangent[keep], n[keep]], axis=1)  # (M, 3 axes, 3)
    light_local = np.einsum("mij,mj->mi", frame, l_world[keep])
    view_local = np.einsum("mij,mj->mi", frame, v_world[keep])
    sigma = confidence_with_distance(light_local[:, 2], view_local[:, 2], distance, d_max(resolution))
    spread = normal_spread(xy, n, geo.tangent, geo.bitangent, geo.texel, resolution)[keep]
    m = int(keep.sum())
    return ReflectanceSamples(light=light_local.astype(np.float32), view=view_local.astype(np.float32),
                              reflectance=r[keep].astype(np.float32), sigma=sigma.astype(np.float32),
                              texel=geo.texel[keep].astype(np.int32), measurement=np.zeros(m, np.int16),
                              resolution=resolution, measurement_names=(name,),
                              footprint=spread.astype(np.float32))


def capture_samples(capture, geometry, face_model, resolution: int = 512, *, measurements=None,
                    erosion: int = 1, min_cosine: float = MIN_COSINE, progress: bool = True,
                    indirect: dict | None = None) -> ReflectanceSamples:
    """Reflectance samples of every measurement of a capture (sec. 4.3).

    Parameters
    ----------
    capture : mifaces.capture.Capture
        The photographs, their lights and the white target. Each point-light
        photograph is turned into reflectance by eq. 4 with the scale the
        white target gives (:meth:`~mifaces.capture.WhiteTarget.reflectance_scale`;
        without one, π: reflectance relative to the lights' intensities);
        its saturated pixels give no sample. Directional lights give every
        texel the same direction and no falloff.
    geometry : mapping
        Measurement name -> (V, 3) vertices of ``face_model``'s topology in
        the capture's world frame (mm): fitted shapes, or the simulator's
        ground truth.
    face_model : mifaces.model.MorphableModel
        Supplies the triangles and the common texture parameterization.
    resolution : int
        R of the R × R texture the samples live in (the paper used 1000).
    measurements : sequence of str, optional
        The measurements to use (default: all that ``geometry`` has).
    indirect : mapping, optional
        Measurement name -> its light bounced off the face (``measurement_samples``' ``indirect``).

    Returns
    -------
    ReflectanceSamples
        All measurements' samples, in the order of ``capture.measurements``,
        each labelled with the region of the triangle it lies on.

    Raises
    ------
    ValueError
        A measurement without geometry, geometry of another model (wrong
        vertex count), an uncalibrated light, a light nobody measured (``unknown``).
    """
    if resolution < 8:
        raise ValueError(f"texture resolution must be at least 8, got {resolution}")
    names = [m.name for m in capture.measurements]
    wanted = list(measurements) if measurements is not None else [n for n in names if n in geometry]
    unknown = [n for n in wanted if n not in names]
    if unknown:
        raise ValueError(f"no measurement(s) {unknown} in the capture; it has {names}")
    missing = [n for n in wanted if n not in geometry]
    if missing:
        raise ValueError(f"no geometry for measurement(s) {missing}")
    if not wanted:
        raise ValueError(f"the geometry names none of the capture's measurements {names}")
    shape = (face_model.vertex_count, 3)
    for name in wanted:
        if np.shape(geometry[name]) != shape:
            raise ValueError(f"geometry of measurement {name!r} has shape {np.shape(geometry[name])}, but the "
                             f"face model {face_model.name!r} has {shape[0]} vertices: geometry of another model?")
        if not np.all(np.isfinite(geometry[name])):
            raise ValueError(f"geometry of measurement {name!r} has NaN or infinite vertices")
    raster = rasterize(face_model.uv, face_model.triangles, (resolution, resolution))
    region_map = texel_regions_of_mesh(face_model.region_map, face_model.uv, face_model.triangles, resolution,
                                       raster)
    scale = capture.reflectance_scale()
    parts = []
    chosen = [m for m in capture.measurements if m.name in wanted]
    for m in progress_bar(chosen, desc="reflectance samples", unit="photo", enabled=progress):
        light = capture.light(m.light)
        light.require_incidence(f"measurement {m.name!r}")
        parts.append(measurement_samples(capture.camera_of(m), light, m.image.pixels, geometry[m.name],
                                         face_model.triangles, face_model.uv, raster, saturated=m.image.saturated,
                                         scale=scale, erosion=erosion, min_cosine=min_cosine, name=m.name,
                                         indirect=None if indirect is None else indirect.get(m.name),
                                         regions=region_map))
    samples = ReflectanceSamples.concatenate(parts)
    samples.label = samples.region(region_map).astype(np.uint8)
    samples.region_map = region_map
    return samples
