"""Reflectance samples from photographs: each photograph resampled into the face model's common
texture parameterization (paper sec. 4.3, 5.3).

Every texel of the face's texture space (:class:`FaceTexture`) is a point on the face fitted to
the photograph (world frame, mm): it is projected into the photograph (:class:`Photograph`) and
read there (bilinear, :func:`read_photograph`), tested for what sees it (the camera, the light:
shadow rays, :func:`unoccluded`), and turned into a reflectance sample by eq. 4 with the
confidence of eq. 10 (:mod:`mifaces.reflectance.samples`). Texels seen or lit at grazing angles,
in cast shadow, outside the image, on saturated pixels or reading another region's light give no
sample. :func:`measurement_samples` does it for one photograph, :func:`capture_samples` for every
photograph of a capture; both return :class:`~mifaces.reflectance.samples.ReflectanceSamples`.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np
import scipy.ndimage

from ..capture.camera import Camera
from ..lights.light import Light
from ..model.mesh import mitsuba_mesh
from ..model.regions import texel_regions_of_mesh
from ..model.texture_space import TextureRaster, rasterize, texel_geometry
from ..runtime.progress import progress as progress_bar
from .environment import LUMINANCE, equivalent_lights
from .footprint import normal_spread
from .mixed_pixels import region_mixed
from .samples import (MIN_COSINE, ReflectanceSamples, confidence_with_distance, d_max, distance_to_missing,
                      reflectance, valid_samples)


@dataclass(frozen=True, eq=False)
class Photograph:
    """One photograph as the samples read it, validated on construction (a ``ValueError`` says what
    does not fit).

    Attributes
    ----------
    camera : Camera
        Calibrated camera (world frame in mm, OpenCV pixel conventions).
    light : Light
        The photograph's light: a point light (``position``, world frame, mm; ``intensity``,
        its radiant intensity in the units of ``pixels``·mm²), a directional one (``direction``,
        the unit vector in the world frame towards the light; ``intensity``, its irradiance in the
        units of ``pixels``) or an environment map (``envmap``, (H, 2H, 3): each texel is read as
        lit by the directional light that stands for the map there,
        :func:`mifaces.reflectance.environment.equivalent_lights`).
    pixels : (H, W, 3) float32
        Linear radiance, the camera's size, finite.
    saturated : (H, W) bool, optional
        Saturated pixels: they give no sample.
    indirect : (H, W, 3) array, optional
        Light bounced off the face, units of ``pixels`` (:mod:`mifaces.reflectance.interreflection`):
        subtracted, since eq. 4 reads direct light.
    name : str
        The measurement's name (the samples' ``measurement_names``).
    """

    camera: Camera
    light: Light
    pixels: np.ndarray
    saturated: np.ndarray | None = None
    indirect: np.ndarray | None = None
    name: str = ""

    def __post_init__(self):
        pixels = np.asarray(self.pixels, np.float32)
        if pixels.shape != (self.camera.height, self.camera.width, 3):
            raise ValueError(f"image of shape {pixels.shape} does not match the camera's "
                             f"{self.camera.height}x{self.camera.width}x3")
        if not np.all(np.isfinite(pixels)):
            raise ValueError(f"image contains {np.count_nonzero(~np.isfinite(pixels))} NaN or infinite values")
        if self.indirect is not None and np.shape(self.indirect) != pixels.shape:
            raise ValueError(f"bounced light of shape {np.shape(self.indirect)} does not match the image's "
                             f"{pixels.shape}")
        object.__setattr__(self, "pixels", pixels)

    def direct(self, points) -> tuple[np.ndarray, np.ndarray]:
        """The direct radiance (N, 3) the photograph shows at world ``points`` (N, 3) (:func:`read_photograph`,
        less the bounced light), and (N,) where it is read (inside the image, away from saturated pixels)."""
        radiance, ok = read_photograph(self.camera, self.pixels, self.saturated, points)
        if self.indirect is not None:
            radiance = radiance - read_photograph(self.camera, self.indirect, None, points)[0]
        return radiance, ok


@dataclass(frozen=True, eq=False)
class FaceTexture:
    """The face model's common texture parameterization at R × R, which every photograph is resampled
    into: the model's triangles and texture coordinates, their raster, and optionally each texel's
    region.

    Attributes
    ----------
    triangles, uv : ndarray
        The face model's triangles (T, 3) and texture coordinates (V, 2).
    raster : mifaces.model.texture_space.TextureRaster
        ``uv`` rasterized at R × R (:func:`~mifaces.model.texture_space.rasterize`).
    regions : (R, R) int array, optional
        Region label of every texel: no sample from a texel that reads another region's pixels
        (:func:`~mifaces.reflectance.mixed_pixels.region_mixed`).
    """

    triangles: np.ndarray
    uv: np.ndarray
    raster: TextureRaster
    regions: np.ndarray | None = None

    def __post_init__(self):
        if self.regions is not None and np.shape(self.regions) != self.raster.triangle.shape:
            raise ValueError(f"regions of shape {np.shape(self.regions)} do not match the {self.resolution}x"
                             f"{self.resolution} texture")

    @property
    def resolution(self) -> int:
        """R."""
        return self.raster.triangle.shape[0]

    @classmethod
    def of(cls, face_model, resolution: int) -> FaceTexture:
        """``face_model``'s texture space at ``resolution``², each texel labelled with the region of the
        triangle covering it (:func:`~mifaces.model.regions.texel_regions_of_mesh`), as the rendered face
        assigns materials."""
        raster = rasterize(face_model.uv, face_model.triangles, (resolution, resolution))
        regions = texel_regions_of_mesh(face_model.region_map, face_model.uv, face_model.triangles, resolution,
                                        raster)
        return cls(face_model.triangles, face_model.uv, raster, regions)


def unoccluded(scene, origin, target, normal, offset: float) -> np.ndarray:
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


def measurement_samples(photograph: Photograph, vertices, texture: FaceTexture, *, scale: float = np.pi,
                        erosion: int = 1, min_cosine: float = MIN_COSINE,
                        offset: float | None = None) -> ReflectanceSamples:
    """Reflectance samples of one photograph (paper sec. 4.3, 5.3).

    Parameters
    ----------
    photograph : Photograph
        The photograph, its camera and light (and the light bounced off the face, to take out).
    vertices : (V, 3) array
        The face in world coordinates (mm) for this measurement, of ``texture``'s topology.
    texture : FaceTexture
        The texture space the samples live in (and each texel's region).
    scale : float
        Scale of eq. 4 (π: a white Lambertian target has r = 1).
    erosion : int
        Texels eroded from the borders of the valid region.
    min_cosine : float
        Samples seen or lit at a cosine below this are dropped.
    offset : float, optional
        How far shadow rays start off the surface (mm; default 10⁻⁴ of the face's extent).

    Returns
    -------
    ReflectanceSamples
        Valid texels only (seen, lit, not grazing, in the image, unsaturated, unmixed); σ by eq. 10.
    """
    camera, light, pixels, regions = photograph.camera, photograph.light, photograph.pixels, texture.regions
    resolution = texture.resolution
    geo = texel_geometry(vertices, texture.triangles, texture.uv, texture.raster)
    p, n = geo.position, geo.normal
    size = float(np.ptp(np.asarray(vertices), axis=0).max())
    offset = 1e-4 * size if offset is None else offset
    scene = mi.load_dict({"type": "scene", "face": mitsuba_mesh(vertices, texture.triangles, texture.uv)})
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
    visible[front] = unoccluded(scene, p[front], np.broadcast_to(camera.position, p[front].shape), n[front], offset)
    if light_target is None:  # the map's light arrives unoccluded along its irradiance vector, by construction
        lit[front] = (e[front] @ LUMINANCE) > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            intensity = e / np.where(cos_l > 0, cos_l, np.nan)[:, None]  # irradiance at normal incidence
    else:
        lit[front] = unoccluded(scene, p[front], light_target[front], n[front], offset)
    radiance, ok = photograph.direct(p)  # the bounced light out: eq. 4 reads direct light
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
                              resolution=resolution, measurement_names=(photograph.name,),
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
        Measurement name -> its light bounced off the face (:attr:`Photograph.indirect`).

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
    texture = FaceTexture.of(face_model, resolution)
    scale = capture.reflectance_scale()
    parts = []
    chosen = [m for m in capture.measurements if m.name in wanted]
    for m in progress_bar(chosen, desc="reflectance samples", unit="photo", enabled=progress):
        light = capture.light(m.light)
        light.require_incidence(f"measurement {m.name!r}")
        photograph = Photograph(capture.camera_of(m), light, m.image.pixels, m.image.saturated,
                                indirect=None if indirect is None else indirect.get(m.name), name=m.name)
        parts.append(measurement_samples(photograph, geometry[m.name], texture, scale=scale, erosion=erosion,
                                         min_cosine=min_cosine))
    samples = ReflectanceSamples.concatenate(parts)
    samples.label = samples.region(texture.regions).astype(np.uint8)
    samples.region_map = texture.regions
    return samples


__all__ = ["Photograph", "FaceTexture", "unoccluded", "read_photograph", "measurement_samples", "capture_samples"]
