"""Lights nobody measured, estimated with the face (issue 26; ``docs/unknown_lights.md``).

A capture's light may be unknown (``"unknown": true`` in ``capture.json``,
:attr:`mifaces.capture.Light.unknown`). The shape fit estimates it with the
face: the directed light of its Phong energy (:mod:`mifaces.shape.energy`:
ambient + a distant light with cast shadows + a specular lobe, then gain and
offset) is free in every fit, starting frontal or from the light's stated
guess, and the photographs of a pose that share the pose's fitted face get
their own light fitted on that face with the geometry and texture held
(:func:`mifaces.shape.fit.fit_light`), so the differently lit photographs
of one face are explained by one albedo. :func:`estimate_lights` turns those
fitted lights into the capture's: one direction per light (the photographs
that share a light share its estimate), and a relative intensity, so every
later stage (reflectance samples, BRDF fits, renders) reads an ordinary
directional light.

Frames and conventions are the capture format's: ``direction`` a unit vector
in the world frame from the subject towards the light; ``intensity`` the
irradiance at normal incidence in pixel value per RGB channel.

What stays ambiguous: the light's absolute intensity against the albedo's
scale (a brighter light on a darker face gives the same photograph). It is
fixed by scaling the estimated intensities so that their mean is
:data:`~mifaces.capture.types.RELATIVE_IRRADIANCE` (the irradiance that brings
a white Lambertian surface facing the light to pixel value 1): intensities are
relative, and so is the reflectance measured under them
(:attr:`Capture.relative_reflectance`; ``brdf.json``'s ``lighting``).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

import mitsuba as mi

from ..capture.types import RELATIVE_IRRADIANCE, Capture
from ..lights.environment import texel_directions, to_world
from ..io.atomic import save_figure, write_json
from ..io.image_files import write_exr
from ..model.mesh import mitsuba_mesh
from ..model.texture_space import rasterize, texel_geometry
from ..runtime.progress import progress as progress_bar
from ..reflectance.environment import estimate_map, transport
from ..reflectance.light_balance import log_light_errors
from ..reflectance.resampling import read_photograph, unoccluded
from ..shape.fit import fit_light
from ..shape.result import ShapeOptions
from ..shape.targets import light_angles

#: File of a result folder holding the capture's lights, estimated and given.
LIGHTS_FILE = "lights.json"
#: Folder of a result folder holding the estimated environment maps, ``<name>.exr``.
LIGHTS_FOLDER = "lights"
#: Picture of the estimated lights beside their photographs.
LIGHTS_PICTURE = "report_lights.png"
#: How the reflectance measured under estimated lights is to be read (``brdf.json`` ``lighting``).
RELATIVE_NOTE = ("lights estimated from the photographs: their intensities are relative (mean "
                 f"{RELATIVE_IRRADIANCE:.6g}) and the albedo and specular reflectance are relative to them: "
                 "light intensity and albedo scale cannot be told apart")


class UnknownLightError(ValueError):
    """An unknown light that cannot be estimated: a map seen in one pose only, or one whose
    photographs got no converged face to estimate it on."""


def check_estimable(capture: Capture) -> None:
    """Raise :class:`UnknownLightError` naming every unknown light :func:`estimate_lights` and
    :func:`estimate_environments` cannot estimate, before any fitting: an environment map whose
    photographs show one pose only (one view of a face under a map cannot tell the map's
    low frequencies from the albedo's)."""
    single = []
    for light in capture.unknown_lights:
        if light.environment:
            views = {m.pose if m.pose is not None else m.name for m in capture.measurements if m.light == light.name}
            if len(views) < 2:
                single.append(light.name)
    if single:
        raise UnknownLightError(f"unknown environment light(s) {single}: their photographs show one pose of the "
                                "face; estimating a map needs two or more (the head turned under the same light), "
                                "or describe them as kind 'directional' (docs/unknown_lights.md)")


def fitted_direction(fit, camera) -> np.ndarray | None:
    """The world-frame unit direction towards the light that ``fit`` (a
    :class:`~mifaces.shape.ShapeFit`) fitted to its photograph, None where it fitted none
    (a shared fit without lighting, a failed fit)."""
    light = (fit.light or {}).get("point", {})
    if "gain" not in light or not fit.converged or not np.all(np.isfinite(light["direction"])):
        return None
    d = camera.rotation.T @ np.asarray(light["direction"], np.float64)
    return d / np.linalg.norm(d)


def fitted_intensity(fit) -> np.ndarray:
    """The RGB irradiance at normal incidence (pixel value, up to the albedo's scale) of the directed
    light ``fit`` fitted: the energy's light colour times the photograph's gain, times
    :data:`RELATIVE_IRRADIANCE` (the energy's diffuse term is albedo x colour x cos, a Lambertian's
    is albedo / pi x irradiance x cos)."""
    light = fit.light["point"]
    return RELATIVE_IRRADIANCE * np.asarray(light["color"], np.float64) * np.asarray(light["gain"], np.float64)


def estimate_lights(capture: Capture, fits) -> Capture:
    """``capture`` with each unknown light replaced by its estimate from the shape fits.

    Parameters
    ----------
    capture : Capture
    fits : list of ShapeFit
        :func:`mifaces.shape.fit_shape`'s, whose fitted lights (``fit.light['point']``, camera
        frame) estimate the lights; only converged fits count.

    Returns
    -------
    Capture
        The same capture, each unknown light now directional (``estimated``, ``relative``): its
        direction the normalised mean of its photographs' fitted directions (world frame), its
        intensity the mean of their :func:`fitted_intensity`, all estimated intensities scaled
        together so that their mean is :data:`RELATIVE_IRRADIANCE` (module docstring). Where every
        light was estimated, without the white target: nothing ties the estimated intensities to its
        units, so reflectance is relative (:attr:`Capture.relative_reflectance`).
        ``capture.metadata['estimated_lights']`` holds per light the photographs it was
        estimated from and their angular spread (degrees).

    Raises
    ------
    UnknownLightError
        For a light of a kind not estimated (:func:`check_estimable`), or one whose photographs
        have no converged fit: it cannot be estimated, and nothing can be measured under it.
    """
    check_estimable(capture)
    by_name = {fit.measurement: fit for fit in fits}
    estimates, missing = {}, []
    for light in capture.unknown_lights:
        if light.environment:  # estimate_environments' work
            continue
        used = [by_name[m.name] for m in capture.measurements if m.light == light.name and m.name in by_name]
        directions = [(fit.measurement, fitted_direction(fit, capture.camera_of(fit.measurement))) for fit in used]
        directions = [(name, d) for name, d in directions if d is not None]
        if not directions:
            missing.append(light.name)
            continue
        names = [name for name, _ in directions]
        stack = np.array([d for _, d in directions])
        mean = stack.sum(axis=0)
        mean /= np.linalg.norm(mean)
        spread = float(np.degrees(np.max(np.arccos(np.clip(stack @ mean, -1, 1)))))
        intensity = np.mean([fitted_intensity(by_name[name]) for name in names], axis=0)
        estimates[light.name] = (mean, intensity, names, spread)
    if missing:
        raise UnknownLightError(f"unknown light(s) {missing}: no photograph under them got a converged shape fit "
                                "to estimate the light on")
    if not estimates:
        return capture
    scale = RELATIVE_IRRADIANCE / float(np.mean([e[1] for e in estimates.values()]))
    lights = tuple(replace(light, direction=estimates[light.name][0], intensity=estimates[light.name][1] * scale,
                           unknown=False, relative=True, estimated=True) if light.name in estimates else light
                   for light in capture.lights)
    metadata = dict(capture.metadata, estimated_lights={
        name: {"photographs": names, "spread_deg": spread} for name, (_, _, names, spread) in estimates.items()})
    # every light estimated: nothing ties their intensities to the white target's units
    white = capture.white_target if len(capture.unknown_lights) < len(capture.lights) else None
    return replace(capture, lights=lights, metadata=metadata, white_target=white)


def as_given(estimated: Capture) -> Capture:
    """``estimated`` (:func:`estimate_lights`'s) with its estimated directional lights read as given:
    what the shape fit of the alternation (:func:`refit_lights`) fits the faces under."""
    return replace(estimated, lights=tuple(replace(light, estimated=False) if light.estimated and light.directional
                                           else light for light in estimated.lights))


def refit_lights(capture: Capture, fits, face_model, **options) -> list:
    """Each photograph under an unknown directional light of ``capture`` with its light fitted again
    (:func:`mifaces.shape.fit.fit_light`) on its pose's face in ``fits``: the faces
    :func:`mifaces.shape.fit_shape` fitted to every photograph of a pose under the first estimates
    (:func:`as_given`). The other photographs keep their fits. One round of the alternation of
    shape and lights (``docs/unknown_lights.md``)."""
    by_name = {fit.measurement: fit for fit in fits}
    # the capture's ambient holds whatever options are given, as in fit_shape
    options["options"] = replace(options.get("options") or ShapeOptions(), ambient=capture.ambient_light)
    out = []
    for fit in fits:
        measurement = next(m for m in capture.measurements if m.name == fit.measurement)
        light = capture.light(measurement.light) if measurement.light else None
        leader = by_name.get(fit.shared_with, fit) if fit.shared_with else fit
        if (light is None or not light.unknown or light.environment or not leader.converged
                or capture.camera_of(measurement) is not capture.camera_of(leader.measurement)):
            out.append(fit)  # (another camera's photograph of the shot: its light was fitted with the leader's)
            continue
        out.append(fit_light(leader, measurement, capture.camera_of(measurement), face_model, light, **options))
    return out


def balance_intensities(capture: Capture, samples) -> Capture:
    """``capture`` with its estimated lights' intensities rescaled so that the face has one albedo
    under all of them.

    The shape fit's intensity (:func:`fitted_intensity`) trades against its ambient term, which the
    reflectance stage does not model: a frontal light and the ambient shade a face alike. The
    reflectance samples (``samples``, :func:`mifaces.reflectance.capture_samples`, taken under
    these lights) say it directly: a texel's reflectance ``r = pixel / (E cos)`` is the same under
    every light where ``E`` is right, and ``1 / s`` of it where ``E`` is ``s`` times too large. The
    log reflectance is fitted as ``a_texel - log s_light`` by alternating a texel's mean and a
    light's median (robust against highlights and shadows the direction errs on), over the samples
    of :data:`~mifaces.reflectance.light_balance.BALANCE_MIN_COSINE` and the texels seen under two or more lights. Each estimated
    light's RGB intensity is then divided by its ``s``. Given lights keep theirs and anchor the
    others (their mean ``log s`` is 0): the estimated intensities are then in the given lights'
    units. Without given lights, the estimated lights' mean intensity is kept at
    :data:`RELATIVE_IRRADIANCE`.

    Returns
    -------
    Capture
        With ``metadata['estimated_lights'][name]['balance']`` the factor ``s`` of each light.
    """
    # environment maps keep the scale their estimate fixed (estimate_environments)
    estimated = [light.name for light in capture.lights if light.estimated and not light.environment]
    given = [light.name for light in capture.lights
             if not light.estimated and not light.unknown and not light.environment]
    if not estimated or len(estimated) + len(given) < 2:
        return capture
    log_s = log_light_errors(capture, samples, estimated + given, anchors=given)  # given lights hold theirs
    if log_s is None or not all(name in log_s for name in estimated):
        return capture
    anchors = [name for name in given if name in log_s]
    factor = {name: float(np.exp(-log_s[name])) for name in estimated}  # r is 1/s too small: E s too large
    scaled = {light.name: light.intensity * factor[light.name] for light in capture.lights if light.name in factor}
    norm = 1.0 if anchors else RELATIVE_IRRADIANCE / float(np.mean([np.mean(v) for v in scaled.values()]))
    info = dict(capture.metadata.get("estimated_lights", {}))  # an estimated map's entry stays
    info.update({name: dict(info.get(name, {}), balance=factor[name] * norm) for name in factor})
    return replace(capture, lights=tuple(replace(light, intensity=scaled[light.name] * norm) if light.name in scaled
                                         else light for light in capture.lights),
                   metadata=dict(capture.metadata, estimated_lights=info))


#: Texture resolution the photographs are read at to estimate a map (:func:`photograph_transport`).
ESTIMATE_RESOLUTION = 96
#: Texels seen at a cosine below this are left out of the estimate (grazing, misregistered).
ESTIMATE_MIN_COSINE = 0.3


def photograph_transport(camera, pixels, saturated, vertices, triangles, uv, raster, size) -> tuple:
    """What one photograph says about a map of ``size`` (width, height): its radiance (N, 3) at the
    texels (N,) of ``raster`` it sees well (visible, at least :data:`ESTIMATE_MIN_COSINE` from
    grazing, unsaturated, inside the image) and their transport matrix (N, J) on the face
    ``vertices`` (world, mm), for :func:`estimate_map`."""
    geo = texel_geometry(vertices, triangles, uv, raster)
    p, n = geo.position, geo.normal
    extent = float(np.ptp(np.asarray(vertices), axis=0).max())
    offset = 1e-4 * extent
    scene = mi.load_dict({"type": "scene", "face": mitsuba_mesh(vertices, triangles, uv)})
    to_camera = camera.position[None, :] - p
    cos_v = np.sum(to_camera / np.linalg.norm(to_camera, axis=1, keepdims=True) * n, axis=1)
    keep = cos_v >= ESTIMATE_MIN_COSINE
    keep[keep] = unoccluded(scene, p[keep], np.broadcast_to(camera.position, p[keep].shape), n[keep], offset)
    radiance, ok = read_photograph(camera, pixels, saturated, p[keep])
    index = np.flatnonzero(keep)[ok]
    directions, solid = texel_directions(*size)
    t = transport(scene, p[index], n[index], to_world(directions, camera), solid, offset, 10.0 * extent)
    return radiance[ok], t, geo.texel[index]


def estimate_environments(capture: Capture, shapes, face_model, resolution: int = ESTIMATE_RESOLUTION,
                          progress: bool = True) -> Capture:
    """``capture`` with each unknown environment light replaced by its map estimated from the
    photographs on the fitted faces (:func:`mifaces.reflectance.environment.estimate_map`).

    Parameters
    ----------
    capture : Capture
    shapes : mapping
        Measurement name -> (V, 3) world vertices of ``face_model`` (the fitted faces).
    face_model : MorphableModel
    resolution : int
        Texture resolution the photographs are read at.

    Returns
    -------
    Capture
        Each unknown environment light now given (``estimated``, ``relative``) with its map
        (:attr:`~mifaces.capture.Light.envmap`); ``metadata['estimated_lights'][name]`` holds the
        photographs it came from and the fit's ``residual``, ``samples`` and ``texels``.

    Raises
    ------
    UnknownLightError
        For a light none of whose photographs has a shape.
    """
    todo = [light for light in capture.unknown_lights if light.environment]
    if not todo:
        return capture
    raster = rasterize(face_model.uv, face_model.triangles, (resolution, resolution))
    maps, info = {}, dict(capture.metadata.get("estimated_lights", {}))
    for light in progress_bar(todo, desc="environment maps", unit="map", enabled=progress):
        used = [m for m in capture.measurements if m.light == light.name and m.name in shapes]
        if not used:
            raise UnknownLightError(f"unknown light {light.name!r}: no photograph under it has a fitted face "
                                    "to estimate the map on")
        parts = [photograph_transport(capture.camera_of(m), m.image.pixels, m.image.saturated, shapes[m.name],
                                      face_model.triangles, face_model.uv, raster, light.envmap_size)
                 for m in used]
        envmap, fit = estimate_map(*zip(*parts), size=light.envmap_size)
        maps[light.name] = envmap
        info[light.name] = {"photographs": [m.name for m in used], **fit}
    lights = tuple(replace(light, envmap=maps[light.name], unknown=False, relative=True, estimated=True)
                   if light.name in maps else light for light in capture.lights)
    white = capture.white_target if any(not light.estimated for light in lights) else None
    return replace(capture, lights=lights, metadata=dict(capture.metadata, estimated_lights=info),
                   white_target=white)


def lights_document(capture: Capture) -> dict:
    """The ``lights.json`` document of ``capture``'s lights, in the capture format's frame and sign
    convention (module docstring): per light ``name``, ``kind``, ``direction`` (directional) or
    ``position_mm`` (point), ``intensity`` (RGB), ``relative`` and ``estimated``; for an
    estimated one the photographs it came from and their spread; and the capture's ``ambient``
    (``"none"``: the shape fit held its ambient term at zero, :attr:`Capture.ambient_light`)."""
    estimated = capture.metadata.get("estimated_lights", {})
    entries = []
    for light in capture.lights:
        entry = {"name": light.name}
        if light.unknown:
            entry.update(kind=light.kind, estimated=False, unknown=True)
        elif light.environment:
            entry.update(kind="environment", size=[int(light.envmap.shape[1]), int(light.envmap.shape[0])])
            if light.estimated:
                entry["map"] = f"{LIGHTS_FOLDER}/{light.name}.exr"
        elif light.directional:
            entry.update(kind="directional", direction=np.asarray(light.direction, np.float64).tolist())
        else:
            entry.update(kind="point", position_mm=None if light.position is None else
                         np.asarray(light.position, np.float64).tolist())
        if light.environment and not light.unknown:
            entry.update(relative=light.relative, estimated=light.estimated)
        elif not light.unknown:
            entry.update(intensity=np.asarray(light.intensity, np.float64).tolist(), relative=light.relative,
                         estimated=light.estimated)
        if light.name in estimated:
            entry.update(estimated[light.name])
        entries.append(entry)
    document = {"lights": entries, "frame": "world frame of the capture; direction: unit vector towards the light",
                "intensity": "irradiance at normal incidence (pixel value) per RGB channel"
                + ("; estimated lights: relative, their mean " + f"{RELATIVE_IRRADIANCE:.6g}" if estimated else ""),
                "ambient": capture.ambient}
    if any(light.environment for light in capture.lights):
        document["map"] = (f"environment maps: latitude-longitude OpenEXR, linear RGB radiance in pixel value, in "
                           "the frame of mifaces.lights.environment.environment_emitter (+y the camera's up, +z towards the "
                           "camera); an estimated map is relative: its largest unoccluded irradiance is "
                           f"{RELATIVE_IRRADIANCE:.6g}")
    return document


def write_lights(out, capture: Capture) -> Path:
    """Write :func:`lights_document` to ``out/lights.json`` and each estimated environment map to
    ``out/lights/<name>.exr`` (atomically); the path of ``lights.json``."""
    path = Path(out) / LIGHTS_FILE
    for light in capture.lights:
        if light.environment and light.estimated:
            (Path(out) / LIGHTS_FOLDER).mkdir(parents=True, exist_ok=True)
            write_exr(Path(out) / LIGHTS_FOLDER / f"{light.name}.exr", light.envmap)
    write_json(path, lights_document(capture))
    return path


def sphere_shading(direction, size: int = 96) -> np.ndarray:
    """A white Lambertian sphere seen by the camera (camera frame: x right, y down, towards the
    viewer -z) lit by a unit light ``direction`` in the camera frame: (size, size) values in
    [0, 1], NaN outside the sphere, so the light's direction reads as where the sphere is bright."""
    u = (np.arange(size) + 0.5) / size * 2 - 1
    x, y = np.meshgrid(u, u)
    r2 = x ** 2 + y ** 2
    normal = np.stack([x, y, -np.sqrt(np.clip(1 - r2, 0, 1))], axis=-1)  # facing the camera: -z
    shade = np.clip(normal @ np.asarray(direction, np.float64), 0, 1)
    return np.where(r2 <= 1, shade, np.nan)


def write_lights_picture(path, capture: Capture, photographs: dict | None = None) -> None:
    """``report_lights.png``: per estimated light, the first photograph taken under it and a sphere
    lit by the estimated direction as the camera sees it (:func:`sphere_shading`), the direction's
    tip marked on the sphere (hollow where it points away from the camera); ``photographs`` maps a
    light's name to a photograph's pixels to show (default: the first measurement's under it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lights = [light for light in capture.lights if light.estimated]
    if not lights:
        return
    widths = [3.4 if light.environment else 1.9 for light in lights]  # a map is twice as wide as high
    fig, axes = plt.subplots(2, len(lights), figsize=(max(sum(widths), 3.6), 4.2), squeeze=False,
                             gridspec_kw={"width_ratios": widths})
    for col, light in enumerate(lights):
        if photographs is not None and light.name in photographs:
            photo = photographs[light.name]
        else:
            photo = next(m.image.pixels for m in capture.measurements if m.light == light.name)
        axes[0, col].imshow(np.clip(photo / max(float(np.percentile(photo, 99.5)), 1e-6), 0, 1) ** (1 / 2.2),
                            cmap="gray" if photo.ndim == 2 else None)
        axes[0, col].set_title(light.name, fontsize=8)
        if light.environment:  # the map: its centre column towards the camera, up the camera's up
            shown = np.asarray(light.envmap, np.float64)
            axes[1, col].imshow(np.clip(shown / max(float(shown.max()), 1e-12), 0, 1) ** (1 / 2.2),
                                extent=(-180, 180, -90, 90), interpolation="nearest")
            axes[1, col].set_title("map (centre: towards the camera)", fontsize=7)
            axes[1, col].set_xticks([-180, 0, 180])
            axes[1, col].set_yticks([-90, 0, 90])
            axes[1, col].tick_params(labelsize=6)
            axes[0, col].axis("off")
            continue
        d = capture.camera.rotation @ np.asarray(light.direction, np.float64)
        size = 96
        axes[1, col].imshow(sphere_shading(d, size), cmap="gray", vmin=0, vmax=1)
        x, y = (d[0] + 1) / 2 * size - 0.5, (d[1] + 1) / 2 * size - 0.5
        axes[1, col].plot([size / 2 - 0.5, x], [size / 2 - 0.5, y], color="tab:orange", lw=1.2)
        axes[1, col].plot(x, y, "o", color="tab:orange", ms=5, mfc="tab:orange" if d[2] < 0 else "none")
        elevation, azimuth = np.degrees(light_angles(d))
        axes[1, col].set_title(f"az {azimuth:+.0f}°, el {elevation:+.0f}°\nintensity {np.mean(light.intensity):.2f}",
                               fontsize=7)
        for ax in axes[:, col]:
            ax.axis("off")
    fig.suptitle("Estimated lights (camera view; azimuth towards\nthe image's right; relative intensity)"
                 if any(not light.environment for light in lights) else "Estimated environment light\n(relative radiance)",
                 fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
