"""Light calibration from pictures of steel (mirror) spheres.

The paper locates its point light "using steel spheres as targets with the
method of Lensch et al." (Fuchs et al. 2005, sec. 3; Lensch et al.,
"Image-based reconstruction of spatially varying materials", EGWR 2001).
Per light condition two pictures of mirror spheres of known radius are
taken from the fixed, calibrated camera: one under the diffuse light, where
each sphere shows its outline, and one under the point light, where each
sphere shows the light's reflection, a small highlight. Then, per sphere:

1. **Locate the sphere** (:func:`locate_spheres`). The camera rays tangent
   to a sphere of radius r whose centre is at distance D form a circular cone
   around the ray to the centre, with half angle α, sin α = r / D. Every unit
   ray d through the sub-pixel outline satisfies a·d = cos α for the cone's
   axis a: linear least squares for w = a / cos α gives the axis and the
   angle, hence the centre D·a, exactly under perspective projection (the
   outline of a sphere is an ellipse, not a circle, away from the image
   centre) and with lens distortion undone.
2. **Find the highlight** (:func:`find_highlight`): the intensity-weighted
   centroid of the brightest blob inside the sphere's image. A sphere whose
   highlight is much fainter than the others' lies in another sphere's
   shadow and is left out.
3. **Reflect the camera ray** through the highlight at the sphere
   (:func:`reflected_ray`): hit point P, normal n = (P - C)/r, reflected
   direction d - 2 (d·n) n. The light lies on that ray.
4. **Triangulate** (:func:`closest_point`): the point nearest to all rays in
   least squares, Σ_i (I - u_i u_iᵀ)(x - p_i) = 0.

All geometry is in the camera frame (OpenCV axes, mm) until the light
position is moved to the capture's world frame at the end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage as ndi
import skimage.filters
import skimage.measure

from .camera import Camera
from .types import SpherePictures

#: Smallest sphere image we try to locate (radius in pixels).
MIN_SPHERE_RADIUS_PX = 4.0
#: Largest part of a sphere's disc a highlight may cover: a point light's
#: reflection is a small spot; a blob over more of the disc is a saturated
#: picture, a uniform one, or no point light at all.
MAX_HIGHLIGHT_FRACTION = 0.05
#: Least ratio of a highlight's peak to the sphere's median brightness.
MIN_HIGHLIGHT_CONTRAST = 4.0
#: Largest RMS distance of the light from the spheres' reflected rays, as a
#: fraction of its distance from the camera: beyond, the spheres disagree
#: (measured on simulated captures: below 0.3 %).
MAX_RAY_RESIDUAL = 0.02


class CalibrationError(ValueError):
    """Steel-sphere pictures from which no light position can be computed."""


@dataclass(frozen=True, eq=False)
class SphereDetection:
    """One sphere found in an outline picture.

    Attributes
    ----------
    center : (3,) float64
        Sphere centre in camera coordinates, mm.
    radius : float
        The known radius, mm.
    center_px : (2,) float64
        Projection of the centre (pixels).
    radius_px : float
        Mean distance of the outline from ``center_px`` (pixels).
    outline_px : (M, 2) float64
        The sub-pixel outline (x, y) it was fitted to.
    cone_residual : float
        RMS of a·d - cos α over the outline rays (radians, roughly).
    """

    center: np.ndarray
    radius: float
    center_px: np.ndarray
    radius_px: float
    outline_px: np.ndarray
    cone_residual: float


@dataclass(frozen=True, eq=False)
class LightCalibration:
    """The result of :func:`calibrate_light`.

    Attributes
    ----------
    position : (3,) float64
        Light position in world coordinates, mm.
    position_camera : (3,) float64
        The same in camera coordinates.
    spheres : tuple of SphereDetection
        The spheres the light was triangulated from.
    highlights_px : (S, 2) float64
        Highlight centroid per sphere (pixels).
    ray_origins, ray_directions : (S, 3) float64
        Reflected rays in camera coordinates (origins on the spheres).
    ray_distances : (S,) float64
        Distance of the light position from each ray, mm: the residual.
    rejected : tuple of SphereDetection
        Spheres found in the outline picture that show no highlight (in
        another sphere's shadow), left out of the triangulation.
    """

    position: np.ndarray
    position_camera: np.ndarray
    spheres: tuple[SphereDetection, ...]
    highlights_px: np.ndarray
    ray_origins: np.ndarray
    ray_directions: np.ndarray
    ray_distances: np.ndarray
    rejected: tuple[SphereDetection, ...] = ()

    @property
    def rms_residual(self) -> float:
        """RMS distance (mm) of the light from the reflected rays."""
        return float(np.sqrt(np.mean(self.ray_distances ** 2)))


def _luminance(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image, np.float64)
    if image.ndim == 3:
        return image[..., :3] @ np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 / sRGB primaries
    return image


def fit_sphere_cone(rays: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    """Centre (camera frame) of a sphere of ``radius`` whose outline is seen along unit ``rays`` (M, 3).

    Returns ``(center, rms)``, with ``rms`` the RMS of ``a·d - cos α``.
    """
    w, *_ = np.linalg.lstsq(rays, np.ones(len(rays)), rcond=None)
    norm = np.linalg.norm(w)
    axis, cos_a = w / norm, 1.0 / norm
    if not 0.0 < cos_a < 1.0 - 1e-9:  # a cone of (numerically) zero angle is no sphere
        raise CalibrationError(f"the outline does not look like a sphere (cos α = {cos_a:.4f})")
    sin_a = np.sqrt(1.0 - cos_a * cos_a)
    rms = float(np.sqrt(np.mean((rays @ axis - cos_a) ** 2)))
    return axis * (radius / sin_a), rms


def locate_spheres(outline: np.ndarray, camera: Camera, radius: float,
                   min_radius_px: float = MIN_SPHERE_RADIUS_PX) -> list[SphereDetection]:
    """Find every sphere of ``radius`` mm in an outline picture.

    The picture shows the spheres darker or brighter than their background.
    Pixels are split by Otsu's threshold (scikit-image); the class the image
    border mostly belongs to is the background; each connected component of
    the other class that does not touch the border and is at least
    ``min_radius_px`` in radius is a sphere. Its outline is the sub-pixel
    iso-contour (marching squares) half way between the sphere's and the
    background's median luminance, fitted by :func:`fit_sphere_cone`.

    Parameters
    ----------
    outline : (H, W) or (H, W, 3) array
        Linear image.
    camera : Camera
    radius : float
        Sphere radius in mm.

    Returns
    -------
    list of SphereDetection, ordered left to right.
    """
    lum = _luminance(outline)
    threshold = skimage.filters.threshold_otsu(lum)
    bright = lum > threshold
    border = np.concatenate([bright[0], bright[-1], bright[:, 0], bright[:, -1]])
    objects = ~bright if border.mean() > 0.5 else bright
    objects = ndi.binary_fill_holes(objects)
    labels, count = ndi.label(objects)
    found = []
    for index, sl in enumerate(ndi.find_objects(labels), start=1):
        if sl is None:
            continue
        mask = labels[sl] == index
        r0, c0 = sl[0].start, sl[1].start
        touches = (r0 == 0 or c0 == 0 or sl[0].stop == lum.shape[0] or sl[1].stop == lum.shape[1])
        if touches or np.sqrt(mask.sum() / np.pi) < min_radius_px:
            continue
        # a window around the component with a margin of background
        pad = 4
        rs = slice(max(r0 - pad, 0), min(sl[0].stop + pad, lum.shape[0]))
        cs = slice(max(c0 - pad, 0), min(sl[1].stop + pad, lum.shape[1]))
        window = lum[rs, cs]
        inside = np.zeros_like(window, bool)
        inside[r0 - rs.start:r0 - rs.start + mask.shape[0], c0 - cs.start:c0 - cs.start + mask.shape[1]] = mask
        core = ndi.binary_erosion(inside, iterations=2)
        ring = ndi.binary_dilation(inside, iterations=3) & ~ndi.binary_dilation(inside, iterations=1)
        if not core.any() or not ring.any():
            continue
        level = 0.5 * (np.median(window[core]) + np.median(window[ring]))
        # only this sphere's pixels: others in the window are set to the background level
        other = (labels[rs, cs] != index) & (labels[rs, cs] > 0)
        window = np.where(other, np.median(window[ring]), window)
        contours = skimage.measure.find_contours(window, level)
        if not contours:
            continue
        contour = max(contours, key=len)  # (row, col)
        px = np.stack([contour[:, 1] + cs.start, contour[:, 0] + rs.start], axis=-1)
        rays = camera.pixel_rays(px)
        try:
            center, rms = fit_sphere_cone(rays, radius)
        except CalibrationError:
            continue
        center_px = camera.project(camera.to_world(center))
        found.append(SphereDetection(center, float(radius), center_px,
                                     float(np.mean(np.linalg.norm(px - center_px, axis=1))), px, rms))
    return sorted(found, key=lambda s: s.center_px[0])


def find_highlight(image: np.ndarray, sphere: SphereDetection, inner: float = 0.98) -> tuple[np.ndarray, float]:
    """Pixel position (x, y) of the light's reflection on ``sphere`` in a point-light picture.

    Within ``inner`` x the sphere's image radius, the pixels above half the
    brightest one form blobs; the one holding the brightest pixel, grown by
    two pixels so that the blurred rim counts too, gives the centroid weighted
    by the luminance above the sphere's dark level (pixel centres at integers).

    Returns
    -------
    (position, peak) : ((2,) float64, float)
        The centroid and the brightest luminance on the sphere: a sphere in
        the shadow of another one shows no highlight, only a faint
        reflection of the other's, and :func:`calibrate_light` drops it by
        comparing peaks.
    """
    lum = _luminance(image)
    h, w = lum.shape
    cx, cy = sphere.center_px
    r = sphere.radius_px
    r0, r1 = max(int(cy - r) - 1, 0), min(int(cy + r) + 2, h)
    c0, c1 = max(int(cx - r) - 1, 0), min(int(cx + r) + 2, w)
    rows, cols = np.mgrid[r0:r1, c0:c1]
    disc = (cols - cx) ** 2 + (rows - cy) ** 2 <= (inner * r) ** 2
    window = np.where(disc, lum[r0:r1, c0:c1], 0.0)
    peak = window.max()
    if not peak > 0:
        raise CalibrationError(f"no highlight on the sphere at pixel ({cx:.1f}, {cy:.1f})")
    blobs, _ = ndi.label(window > 0.5 * peak)
    blob = blobs == blobs[np.unravel_index(np.argmax(window), window.shape)]
    if blob.sum() > MAX_HIGHLIGHT_FRACTION * disc.sum() or peak < MIN_HIGHLIGHT_CONTRAST * np.median(window[disc]):
        raise CalibrationError(f"no distinct highlight on the sphere at pixel ({cx:.1f}, {cy:.1f}): the brightest "
                               f"blob covers {blob.sum() / disc.sum():.0%} of its disc at {peak:.3g}, its median "
                               f"{np.median(window[disc]):.3g} (a saturated or uniform picture?)")
    blob = ndi.binary_dilation(blob, iterations=2) & disc
    dark = disc & ~ndi.binary_dilation(blob, iterations=2)
    background = np.median(window[dark]) if dark.sum() > 10 else 0.0
    weight = np.where(blob, np.clip(window - background, 0, None), 0.0)
    total = weight.sum()
    return np.array([(weight * cols).sum() / total, (weight * rows).sum() / total]), float(peak)


def reflected_ray(camera: Camera, sphere: SphereDetection, highlight_px) -> tuple[np.ndarray, np.ndarray]:
    """The camera ray through ``highlight_px`` mirrored at the sphere: ``(origin, direction)`` in camera frame."""
    d = camera.pixel_rays(np.asarray(highlight_px, np.float64))
    c, r = sphere.center, sphere.radius
    b = d @ c
    disc = b * b - (c @ c - r * r)
    if disc < 0:  # the highlight sits on the rim within the outline error: take the closest point
        disc = 0.0
    t = b - np.sqrt(disc)
    p = t * d
    n = (p - c) / r
    u = d - 2.0 * (d @ n) * n
    return p, u / np.linalg.norm(u)


def closest_point(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The point with the least sum of squared distances to the lines ``origin + s direction``.

    Solves Σ_i (I - u_i u_iᵀ) x = Σ_i (I - u_i u_iᵀ) p_i (unit u_i).
    """
    origins = np.asarray(origins, np.float64)
    u = np.asarray(directions, np.float64)
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    projectors = np.eye(3)[None] - u[:, :, None] * u[:, None, :]
    a = projectors.sum(axis=0)
    b = np.einsum("nij,nj->i", projectors, origins)
    if np.linalg.cond(a) > 1e8:
        raise CalibrationError("the reflected rays are (nearly) parallel; the light position is undetermined")
    return np.linalg.solve(a, b)


def calibrate_light(spheres: SpherePictures, camera: Camera, expected_count: int | None = None,
                    min_highlight: float = 0.2) -> LightCalibration:
    """Light position from the two steel-sphere pictures of one light condition.

    Parameters
    ----------
    spheres : SpherePictures
        ``outline`` and ``highlight`` pictures and the sphere radius (mm).
    camera : Camera
    expected_count : int, optional
        Raise if a different number of spheres is found in the outline picture.
    min_highlight : float
        A sphere whose brightest pixel in the highlight picture is below this
        fraction of the brightest sphere's shows no highlight (it lies in the
        shadow of another sphere, or the reflection is hidden) and is left out
        of the triangulation; it is listed in ``LightCalibration.rejected``.

    Returns
    -------
    LightCalibration

    Raises
    ------
    CalibrationError
        Fewer than two spheres found or with a distinct highlight (a
        saturated or uniform picture has none: :data:`MAX_HIGHLIGHT_FRACTION`,
        :data:`MIN_HIGHLIGHT_CONTRAST`), parallel rays, or spheres that
        disagree beyond :data:`MAX_RAY_RESIDUAL`.
    """
    found = locate_spheres(spheres.outline.pixels, camera, spheres.radius)
    if expected_count is not None and len(found) != expected_count:
        raise CalibrationError(f"found {len(found)} spheres in {spheres.outline.path.name}, "
                               f"expected {expected_count}")
    if len(found) < 2:
        raise CalibrationError(f"found {len(found)} sphere(s) in {spheres.outline.path.name}; "
                               "triangulating the light needs at least two")
    located = []
    for sphere in found:
        try:
            located.append((sphere, *find_highlight(spheres.highlight.pixels, sphere)))
        except CalibrationError:
            located.append((sphere, None, 0.0))
    brightest = max(peak for _, _, peak in located)
    used = [(s, h) for s, h, peak in located if h is not None and peak >= min_highlight * brightest]
    rejected = tuple(s for s, h, peak in located if h is None or peak < min_highlight * brightest)
    if len(used) < 2:
        raise CalibrationError(f"{len(used)} of the {len(found)} spheres show a highlight in "
                               f"{spheres.highlight.path.name}; triangulating the light needs at least two")
    highlights, origins, directions = [], [], []
    for sphere, h in used:
        p, u = reflected_ray(camera, sphere, h)
        highlights.append(h)
        origins.append(p)
        directions.append(u)
    origins, directions = np.array(origins), np.array(directions)
    x = closest_point(origins, directions)
    offsets = x - origins
    along = np.einsum("ij,ij->i", offsets, directions)
    if np.any(along <= 0):
        raise CalibrationError("the triangulated light lies behind a sphere's reflected ray")
    distances = np.linalg.norm(offsets - along[:, None] * directions, axis=1)
    rms = float(np.sqrt(np.mean(distances ** 2)))
    if rms > MAX_RAY_RESIDUAL * np.linalg.norm(x):
        raise CalibrationError(f"the spheres disagree: the light lies {rms:.1f} mm (RMS) from their reflected rays, "
                               f"more than {MAX_RAY_RESIDUAL:.0%} of its distance {np.linalg.norm(x):.0f} mm")
    return LightCalibration(camera.to_world(x), x, tuple(s for s, _ in used), np.array(highlights), origins,
                            directions, distances, rejected)
