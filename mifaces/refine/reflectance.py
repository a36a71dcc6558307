"""Analysis by synthesis through Mitsuba: the texture-space fit refined by
differentiating renders of the fitted face against the photographs.

The texture-space fit (:func:`mifaces.reflectance.estimate.fit_brdf`, the
paper's method, sec. 4.3-5.3) reads each texel as if it were lit by the
light alone and seen through an ideal pixel: interreflection (eye sockets,
nostrils, under the lips), a lamp of finite size, and the resampling and
pixel footprint that blur thin curved regions (lips, eyebrows, hair) are not
modelled, so small regions' highlights read too weak. :func:`refine_estimate`
starts from that fit and minimises the difference between Mitsuba renders of
the fitted face and the photographs themselves:

    E(θ, ρ_d, g) = Σ_k 1/|M_k| Σ_{p ∈ M_k} Σ_c ψ_ε((e^{g_l(k) - ḡ} I_k(θ, ρ_d)[p, c] - s J_k[p, c]) / μ_k),

where I_k is the path-traced render of measurement k (its face mesh, its
camera, its light, the per-region plugins with parameters θ over the albedo
texture ρ_d), g_l the log gain of light l, the light of measurement k (ḡ
their mean: the overall scale belongs to the albedo and the white target; a
calibrated lamp is off in distance by about a percent, its irradiance by
twice that, which with the lights held the glossy parameters absorb), J_k
the photograph (s = s_white/π puts it in the renderer's
units, eq. 4 with the white target's scale), M_k the pixels the face covers
(eroded by one pixel at silhouettes, saturated pixels left out), μ_k the
photograph's mean over M_k and ψ_ε(r) = sqrt(r² + ε²) - ε the Charbonnier
penalty (quadratic below ε, linear above: misregistered pixels cannot
dominate). Gradients come from Dr.Jit's reverse mode through Mitsuba's path
replay backpropagation (``prb``; Vicini et al., "Path Replay
Backpropagation", SIGGRAPH 2021); the steps are Adam's, one photograph per
step in turn, and the result is the mean of the last iterates
(Polyak-Ruppert averaging, :class:`~mifaces.refine.schedule.IterateAverage`).
Parameters stay inside their ranges (``Parameter.lower`` and
``upper``) by the reparameterisation of the texture-space fit
(:class:`~mifaces.reflectance.fit.parameters.ParameterSpace`, a sigmoid or its
logarithmic form); the albedo, optionally a variable too, by a smooth
multiplicative correction (:class:`AlbedoCorrection`).

Each photograph's scene is the one face-scene builder's
(:meth:`mifaces.render.FaceScene.scene`) with the differentiable integrator,
a film cropped to the face, and the light of the capture: a point light, a
directional light, or, where the capture states ``lamp_radius_mm`` (in its
``metadata``) or the caller gives ``lamp_radius``, a spherical area light of
that radius and the same radiant intensity; or an environment map (Mitsuba's
``envmap``). An estimated map (:attr:`mifaces.capture.Light.estimated`) is a
variable too: its log radiance per texel, the mean held, with a smoothness
prior (:attr:`RefineSchedule.environment_learning_rate`); under a map the
glossy parameters start at the model's start values
(:attr:`RefineSchedule.restart_under_maps`). No other geometry. The scenes are built once; each step writes the parameters
(opaque, so the kernels compiled on the first pass over the photographs are
reused) and renders.

The refined estimate is returned only if it lowers the loss on pixels the
refinement did not fit: blocks of each photograph's face pixels held out of E
(:attr:`RefineSchedule.holdout`), rendered before and after with the same
seed; otherwise the texture-space fit comes back, and ``refinement`` says why.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np
from scipy.ndimage import binary_erosion

from .. import brdf as brdf_models
from ..model.regions import REGIONS
from ..progress import progress as progress_bar
from ..render import FaceScene, mitsuba_sensor
from .albedo_correction import AlbedoCorrection
from ..reflectance.environment import neighbour_pairs
from ..reflectance.fit.parameters import ParameterSpace
from ..reflectance.result import BRDFEstimate
from .schedule import ALBEDO, LIGHT_GAIN, IterateAverage, RefineSchedule, environment_variable, holdout_pixels


#: Key of a capture's ``metadata`` that gives the lamp's radius (mm).
LAMP_RADIUS_KEY = "lamp_radius_mm"
#: Fewest pixels (over all photographs, at the render resolution) for a region's parameters to be variables.
MIN_PIXELS = 40


def image_loss(image, target, weight, epsilon: float):
    """The robust image loss of one photograph (the module docstring's E_k).

    Parameters
    ----------
    image, target : mi.TensorXf (H, W, 3)
        Render and photograph, both divided by the photograph's mean μ_k over
        the mask (the residual is relative).
    weight : mi.TensorXf (H, W, 3)
        1/|M_k| on the masked pixels, 0 elsewhere.
    epsilon : float
        ε of ψ_ε(r) = sqrt(r² + ε²) - ε.

    Returns
    -------
    mi.Float
        Σ weight · ψ_ε(image - target), differentiable in ``image``.
    """
    r = image - target
    return dr.sum(weight * (dr.sqrt(r * r + epsilon * epsilon) - epsilon), axis=None).array


@dataclass(eq=False)
class _Photograph:
    """One measurement's scene, photograph and mask, at the render resolution."""

    name: str
    scene: mi.Scene
    params: mi.SceneParameters
    target: mi.TensorXf
    #: the fitted pixels' weight, and the held-out pixels' (:func:`image_loss`)
    weight: mi.TensorXf
    heldout_weight: mi.TensorXf
    #: 1 / the photograph's mean over the mask (μ_k)
    scale: float
    #: scene parameter key -> (region, parameter name)
    keys: dict
    albedo_keys: list
    #: region -> covered pixels
    pixels: dict
    #: the measurement's light, and its index in :attr:`RefineProblem.lights`
    light: str = ""
    light_index: int = 0
    #: the scene parameter of an environment light's map, if the light is one
    envmap_key: str | None = None


def _box_mean(a: np.ndarray, k: int) -> np.ndarray:
    """``a`` (H, W, ...) averaged over k × k blocks (H, W cut to multiples of k)."""
    h, w = a.shape[0] // k * k, a.shape[1] // k * k
    a = a[:h, :w]
    return a.reshape(h // k, k, w // k, k, *a.shape[2:]).mean(axis=(1, 3))


def coverage(scene: mi.Scene, camera, region_map: np.ndarray) -> np.ndarray:
    """Region label (``region_map`` at the texture coordinate the pixel centre's
    ray hits) of each pixel of ``camera``'s image of ``scene``; 0 where the
    ray hits nothing. (H, W) int."""
    ys, xs = np.mgrid[0:camera.height, 0:camera.width]
    directions = camera.pixel_rays(np.stack([xs, ys], -1).reshape(-1, 2)) @ camera.rotation  # to world: R^T d
    origin = [mi.Float(np.full(len(directions), c, np.float32)) for c in camera.position]
    ray = mi.Ray3f(mi.Point3f(*origin), mi.Vector3f(np.ascontiguousarray(directions.T, np.float32)))
    si = scene.ray_intersect(ray)
    hit = np.asarray(si.is_valid())
    uv = np.asarray(si.uv).T
    r = region_map.shape[0]
    col = np.clip((uv[:, 0] * r).astype(int), 0, r - 1)
    row = np.clip((uv[:, 1] * r).astype(int), 0, r - 1)
    labels = np.where(hit, np.maximum(region_map[row, col], 1), 0)
    return labels.reshape(camera.height, camera.width)


def _light(capture, measurement, lamp_radius: float | None) -> tuple:
    """The measurement's :class:`~mifaces.capture.Light`, and the sphere lamp that replaces its point
    light (or None)."""
    light = capture.light(measurement.light)
    if light.environment or light.directional or light.position is None or not lamp_radius:
        return light, None
    radiance = np.asarray(light.intensity, np.float64) / (np.pi * lamp_radius ** 2)  # same intensity, I = L π r²
    return light, {"type": "sphere", "center": [float(x) for x in light.position], "radius": float(lamp_radius),
                    "emitter": {"type": "area", "radiance": {"type": "rgb", "value": radiance.tolist()}}}


@dataclass(eq=False)
class PhotographView:
    """One measurement's photograph and its differentiable render, at the
    render resolution, cropped to the face.

    Attributes
    ----------
    scene : mi.Scene
        The face (:meth:`FaceScene.scene`) under the measurement's light, with
        the given integrator and a film cropped to ``mask``'s bounding box.
    params : mi.SceneParameters
    target : mi.TensorXf (H, W, 3)
        The photograph in the renderer's units divided by its mean over the mask (μ_k).
    mask : (H, W) bool
        Pixels whose every photograph pixel the face covers (eroded by one
        pixel at silhouettes), none saturated.
    labels : (H, W) int
        Region label at each pixel (:func:`coverage`, sampled at the render resolution).
    scale : float
        1/μ_k: multiplies a render to compare it with ``target``.
    light_kind : str
        ``'point'``, ``'directional'``, ``'sphere'`` or ``'environment'``.
    """

    scene: mi.Scene
    params: mi.SceneParameters
    target: mi.TensorXf
    mask: np.ndarray
    labels: np.ndarray
    scale: float
    light_kind: str


def mask_weight(mask: np.ndarray) -> mi.TensorXf:
    """The weight of :func:`image_loss`: 1/|M_k| on the (H, W) ``mask``'s pixels (each channel a third), 0 elsewhere."""
    weight = np.repeat(mask[..., None], 3, axis=2) / (3.0 * max(int(mask.sum()), 1))
    return mi.TensorXf(np.ascontiguousarray(weight, np.float32))


def photograph_view(capture, m, face: FaceScene, brdf: dict, albedo: np.ndarray, region_map: np.ndarray,
                    scale: np.ndarray, lamp_radius: float | None, downsample: int, spp: int, integrator: dict, *,
                    normals: np.ndarray | None = None, specular: np.ndarray | None = None,
                    sample_border: bool = False) -> PhotographView:
    """The render of measurement ``m`` of ``capture`` set against its photograph.

    Parameters
    ----------
    capture : Capture
    m : Measurement
    face : FaceScene
        The face's meshes in ``m``'s pose (world frame, mm).
    brdf, albedo : dict, (R, R, 3) array
        The ``brdf.json`` layout and the albedo map (:meth:`FaceScene.scene`).
    region_map : (R', R') uint8
        Region labels in texture space (the pixels' labels).
    scale : (3,) array
        Photograph value -> renderer units (s_white/π, eq. 4).
    lamp_radius : float or None
        Radius (mm) of a spherical lamp in place of a point light.
    downsample : int
        Render at 1/``downsample`` of the camera's resolution against the
        photograph averaged over blocks.
    spp : int
    integrator : dict
        The Mitsuba integrator (``prb``, ``direct_projective``, ...).
    normals, specular : arrays, optional
        Per-texel normal and specular maps (:meth:`FaceScene.scene`).
    sample_border : bool
        The film's ``sample_border``: samples beyond the crop, for a projective
        integrator's gradients of geometry crossing the film's edge.

    Returns
    -------
    PhotographView
    """
    k = downsample
    camera = capture.camera
    light, lamp = _light(capture, m, lamp_radius)
    kind = ("sphere" if lamp is not None else "environment" if light.environment
            else "directional" if light.directional else "point")
    description = face.scene(brdf, albedo, camera, light, normals=normals, specular=specular)
    labels = coverage(mi.load_dict({"type": "scene", **{key: v for key, v in description.items()
                                                      if key.startswith("face_")}}), camera, region_map)
    covered = binary_erosion(labels > 0, iterations=1) & ~m.image.saturated
    # the render's pixels: those whose every photograph pixel is covered
    low_mask = _box_mean(covered.astype(np.float64), k) > 0.999
    if not low_mask.any():
        raise ValueError(f"measurement {m.name!r}: the face covers no unsaturated pixel")
    rows, cols = np.nonzero(low_mask)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    target = _box_mean(m.image.pixels * scale, k)[r0:r1, c0:c1]
    mask = low_mask[r0:r1, c0:c1]
    mean = float(target[mask].mean())
    sensor = mitsuba_sensor(camera, spp)
    sensor["film"] = dict(sensor["film"], width=camera.width // k, height=camera.height // k,
                          crop_offset_x=int(c0), crop_offset_y=int(r0), crop_width=int(c1 - c0),
                          crop_height=int(r1 - r0), rfilter={"type": "gaussian", "stddev": 0.5 / k}
                          if k == 1 else {"type": "box"}, sample_border=bool(sample_border))
    description["sensor"] = sensor
    description["integrator"] = integrator
    if lamp is not None:
        description["light"] = lamp
    scene = mi.load_dict(description)
    low_labels = labels[: labels.shape[0] // k * k, : labels.shape[1] // k * k][::k, ::k][r0:r1, c0:c1]
    return PhotographView(scene, mi.traverse(scene), mi.TensorXf(np.ascontiguousarray(target / mean, np.float32)),
                          mask, low_labels, 1.0 / mean, kind)


class RefineProblem:
    """The photographs of a capture as differentiable renders of a fitted face.

    Parameters
    ----------
    estimate : BRDFEstimate
        The texture-space fit to start from.
    capture : Capture
    shapes : mapping
        Measurement name -> (V, 3) world vertices of ``face_model``.
    face_model : MorphableModel
    schedule : RefineSchedule
    lamp_radius : float or None
        Radius (mm) of a spherical lamp in place of each point light.
    measurements : sequence of str, optional
        The photographs to use (default: those of the estimate).
    seed : int
        Chooses the held-out pixels (:attr:`RefineSchedule.holdout`).

    Attributes
    ----------
    photographs : list of _Photograph
    spaces : dict
        Region -> :class:`ParameterSpace` of its glossy parameters (diffuse and
        per-region fixed parameters held).
    variables : dict
        Name (``<region>.<k>``, ``albedo``, ``light_gain``, ``environment:<light>``) -> start value of
        each unconstrained variable.
    """

    def __init__(self, estimate: BRDFEstimate, capture, shapes, face_model, schedule: RefineSchedule,
                 lamp_radius: float | None = None, measurements=None, seed: int = 0):
        self.estimate, self.schedule = estimate, schedule
        self.rng = np.random.default_rng([seed, 27])
        self.model = brdf_models.model(estimate.model, **estimate.options)
        brdf, albedo = estimate.to_json(), estimate.albedo.albedo
        names = list(measurements or estimate.measurements)
        scale = (capture.white_target.reflectance_scale() / np.pi if capture.white_target is not None
                 else np.ones(3))
        self.light_kinds = set()
        self.photographs = [self._photograph(capture, m, shapes[m.name], face_model, brdf, albedo, scale,
                                             lamp_radius)
                            for m in capture.measurements if m.name in names and m.name in shapes]
        if not self.photographs:
            raise ValueError(f"no photograph to refine on: none of {names} has a shape")
        pixels = {}
        for photo in self.photographs:
            for region, n in photo.pixels.items():
                pixels[region] = pixels.get(region, 0) + n
        self.pixels = pixels
        self.lights = sorted({p.light for p in self.photographs})
        #: the glossy parameters start at the model's start values, not the texture-space fit's
        self.restarted = (schedule.restart_under_maps and
                          any(capture.light(name).environment for name in self.lights))
        for photo in self.photographs:
            photo.light_index = self.lights.index(photo.light)
        #: each region variable's value in the texture-space fit (where it starts unless restarted)
        self.spaces, self.variables, self.fitted = {}, {}, {}
        for region, fit in estimate.fits.items():
            if pixels.get(region, 0) < MIN_PIXELS or region in schedule.held_regions:
                continue
            fixed = {k: v for k, v in fit.params.items()
                     if k not in {p.name for p in self.model.specular_parameters()}
                     or k in self.model.fixed_in_region(region)}
            space = ParameterSpace(self.model, fixed=fixed)
            if not len(space):
                continue
            self.spaces[region] = space
            start = dict(fit.params)
            if self.restarted:  # the one-direction reading of a map biases the glossy fit: start afresh
                start.update({k: v for k, v in self.model.start_values().items() if k not in fixed})
            for i, (x, x_fit) in enumerate(zip(space.vector(start), space.vector(fit.params))):
                self.variables[f"{region}.{i}"] = float(x)
                self.fitted[f"{region}.{i}"] = float(x_fit)
        self.albedo = None
        if schedule.albedo_learning_rate is not None:
            self.albedo = AlbedoCorrection(albedo, schedule.albedo_cell)
            self.variables[ALBEDO] = self.albedo.start()
        if schedule.light_gain_learning_rate is not None and len(self.lights) > 1:
            self.variables[LIGHT_GAIN] = np.zeros(len(self.lights))
        #: estimated environment light -> :class:`_EnvironmentVariable`
        self.environments = {}
        if schedule.environment_learning_rate is not None:
            for name in self.lights:
                light = capture.light(name)
                if light.environment and light.estimated and light.envmap is not None:
                    envmap = np.asarray(light.envmap, np.float64)
                    log = np.log(np.maximum(envmap, ENVMAP_FLOOR * max(float(envmap.mean()), 1e-30)))
                    self.environments[name] = _EnvironmentVariable(log.shape, float(log.mean()),
                                                                   _neighbour_pairs(log.shape),
                                                                   _padded_index(log.shape))
                    self.variables[environment_variable(name)] = log

    def _photograph(self, capture, m, vertices, face_model, brdf, albedo, scale, lamp_radius) -> _Photograph:
        view = photograph_view(capture, m, FaceScene(face_model, vertices), brdf, albedo, self.estimate.region_map,
                               scale, lamp_radius, self.schedule.downsample, self.schedule.spp,
                               {"type": "prb", "max_depth": int(self.schedule.max_depth), "hide_emitters": True})
        self.light_kinds.add(view.light_kind)
        free = {p.name for p in self.model.specular_parameters()}
        keys, albedo_keys = {}, []
        for key in view.params.keys():
            parts = key.split(".")
            if parts[0].startswith("face_") and len(parts) > 2 and parts[1] == "bsdf":
                region = parts[0][len("face_"):].rsplit("_", 1)[0]
                if parts[2] in free:
                    keys[key] = (region, parts[2])
                elif parts[2:] == ["diffuse_reflectance", "data"]:
                    albedo_keys.append(key)
        names = {label: name for name, label in REGIONS.items()}
        pixels = {}
        for label, n in zip(*np.unique(view.labels[view.mask], return_counts=True)):
            region = names.get(int(label), "skin")
            pixels[region] = pixels.get(region, 0) + int(n)
        held = holdout_pixels(view.mask, self.schedule.holdout, self.schedule.holdout_block, self.rng)
        envmap_key = "environment.data" if "environment.data" in view.params else None
        return _Photograph(m.name, view.scene, view.params, view.target, mask_weight(view.mask & ~held),
                           mask_weight(held), view.scale, keys, albedo_keys, pixels, m.light, envmap_key=envmap_key)

    # -- the parameters as Dr.Jit values of the unconstrained variables --------
    def values(self, variables: dict) -> dict:
        """Region -> {parameter: Dr.Jit value} (differentiable in ``variables``)."""
        out = {}
        for region, space in self.spaces.items():
            u = [variables[f"{region}.{i}"] for i in range(len(space))]
            out[region] = space.drjit_params(u)
        return out

    def set(self, photo: _Photograph, variables: dict) -> None:
        """Write the parameters of ``variables`` into ``photo``'s scene."""
        values = self.values(variables)
        for key, (region, name) in photo.keys.items():
            if region in values:
                photo.params[key] = values[region][name]
        if self.albedo is not None:
            texture = self.albedo.albedo(variables[ALBEDO])
            for key in photo.albedo_keys:
                photo.params[key] = texture
        if photo.light in self.environments and photo.envmap_key is not None:
            photo.params[photo.envmap_key] = padded_envmap(self.environment_map(photo.light, variables),
                                                           self.environments[photo.light].padded)
        photo.params.update()

    def environment_map(self, light: str, variables: dict):
        """Estimated environment light ``light``'s map (H, W, 3) as a differentiable TensorXf: exp of
        its log-radiance variable, the mean log held at its start's."""
        environment = self.environments[light]
        x = variables[environment_variable(light)]
        return mi.TensorXf(dr.exp(x.array - dr.mean(x.array) + environment.mean_log), environment.shape)

    def environment_prior(self, variables: dict):
        """The estimated maps' smoothness prior (:attr:`RefineSchedule.environment_smoothness`): mi.Float."""
        total = mi.Float(0.0)
        for light, environment in self.environments.items():
            x = variables[environment_variable(light)].array
            for a, b in environment.pairs:
                d = dr.gather(mi.Float, x, a) - dr.gather(mi.Float, x, b)
                total += dr.mean(d * d)
        return self.schedule.environment_smoothness * total

    def gain(self, photo: _Photograph, variables: dict):
        """The factor on ``photo``'s light, exp(g_l - mean g) (differentiable), or 1 where the light
        gains are not variables (one light, or ``light_gain_learning_rate`` None)."""
        if LIGHT_GAIN not in self.variables:
            return 1.0
        g = variables[LIGHT_GAIN]
        return dr.exp(dr.gather(mi.Float, g, photo.light_index) - dr.mean(g))

    def light_gains(self, variables: dict) -> dict:
        """Light name -> its fitted factor exp(g_l - mean g) (1 for each where they are not variables)."""
        if LIGHT_GAIN not in self.variables:
            return {name: 1.0 for name in self.lights}
        g = np.asarray(variables[LIGHT_GAIN], np.float64)
        return {name: float(np.exp(x - g.mean())) for name, x in zip(self.lights, g)}

    def loss(self, photo: _Photograph, variables: dict, spp: int, seed: int, weight: mi.TensorXf | None = None):
        """E_k of ``photo`` (:func:`image_loss`) rendered with ``spp`` samples over ``weight`` (default:
        the fitted pixels'): a differentiable mi.Float."""
        self.set(photo, variables)
        image = mi.render(photo.scene, photo.params, spp=spp, seed=seed, seed_grad=seed + 1)
        loss = image_loss(image * (photo.scale * self.gain(photo, variables)), photo.target,
                          photo.weight if weight is None else weight, self.schedule.epsilon)
        return loss + self.environment_prior(variables) if self.environments and weight is None else loss

    def total_loss(self, variables: dict, spp: int, seed: int = 1 << 20) -> dict:
        """Mean E_k over the photographs on the fitted and on the held-out pixels (no gradients;
        each photograph rendered once, with the same seed for a given ``seed``)."""
        fit, held = [], []
        with dr.suspend_grad():
            for i, p in enumerate(self.photographs):
                self.set(p, variables)
                image = mi.render(p.scene, p.params, spp=spp, seed=seed + 2 * i) * (p.scale * self.gain(p, variables))
                fit.append(image_loss(image, p.target, p.weight, self.schedule.epsilon)[0])
                held.append(image_loss(image, p.target, p.heldout_weight, self.schedule.epsilon)[0])
        return {"fit": float(np.mean(fit)), "heldout": float(np.mean(held))}

    def estimate_of(self, variables: dict, refinement: dict) -> BRDFEstimate:
        """The estimate with each refined region's parameters (and the albedo)
        from ``variables``, and the ``refinement`` record."""
        fits = dict(self.estimate.fits)
        for region, space in self.spaces.items():
            x = np.array([float(np.asarray(variables[f"{region}.{i}"])[0]) for i in range(len(space))])
            params = dict(fits[region].params)
            params.update({k: v for k, v in space.values(x).items() if k in params})
            # the region fit's intervals were around its own optimum, not the refined one
            fits[region] = dataclasses.replace(fits[region], params=params, uncertainty={})
        albedo = self.estimate.albedo
        if self.albedo is not None:
            with dr.suspend_grad():
                texture = np.asarray(self.albedo.albedo(variables[ALBEDO]), np.float32)
            albedo = dataclasses.replace(albedo, albedo=texture, std=None)
        return dataclasses.replace(self.estimate, fits=fits, albedo=albedo, refinement=refinement)

    def environment_maps(self, variables: dict) -> dict:
        """Estimated environment light -> its map (H, W, 3) float32 at ``variables``."""
        with dr.suspend_grad():
            return {light: np.asarray(self.environment_map(light, variables), np.float32)
                    for light in self.environments}


#: Radiance an estimated map's texel is floored at before its logarithm is taken, relative to the map's mean
#: (a texel the estimate left black can still brighten, and the smoothness prior stays finite).
ENVMAP_FLOOR = 1e-2


def _neighbour_pairs(shape) -> list:
    """Flat index pairs (UInt32, UInt32) of each (H, W, 3) map's texel and channel with the
    neighbours of :func:`~mifaces.reflectance.environment.neighbour_pairs`: the right neighbours,
    then those below (the prior averages each group)."""
    h, w, c = shape
    pairs = neighbour_pairs(w, h)[:, :, None] * c + np.arange(c)  # (P, 2, channel)
    return [(mi.UInt32(group[:, 0].ravel().astype(np.uint32)), mi.UInt32(group[:, 1].ravel().astype(np.uint32)))
            for group in (pairs[:w * h], pairs[w * h:])]


def _padded_index(shape) -> mi.UInt32:
    """The flat index into an (H, W, 3) map of each element of :func:`padded_envmap`'s (H, W + 2, 3)."""
    h, w, c = shape
    rows, cols, chans = np.meshgrid(np.arange(h), (np.arange(w + 2) - 1) % w, np.arange(c), indexing="ij")
    return mi.UInt32(((rows * w + cols) * c + chans).ravel().astype(np.uint32))


def padded_envmap(envmap: mi.TensorXf, index: mi.UInt32 | None = None) -> mi.TensorXf:
    """An (H, W, 3) map as Mitsuba's ``envmap`` stores its ``data``: (H, W + 2, 3), the last column
    before the first and the first after the last (it wraps round in azimuth). ``index``:
    :func:`_padded_index` of its shape, where it was built once."""
    h, w, c = envmap.shape
    index = _padded_index(envmap.shape) if index is None else index
    return mi.TensorXf(dr.gather(mi.Float, envmap.array, index), (h, w + 2, c))


@dataclasses.dataclass(frozen=True)
class _EnvironmentVariable:
    """An estimated map the refinement fits: its shape, its start's mean log radiance (held), and
    the index arrays of its smoothness prior (:func:`_neighbour_pairs`) and of Mitsuba's padded
    layout (:func:`_padded_index`), built once."""

    shape: tuple
    mean_log: float
    pairs: list
    padded: object


class _kernel_history:
    """Record Dr.Jit's kernel launches inside the ``with`` block."""

    def __enter__(self):
        self.was = dr.flag(dr.JitFlag.KernelHistory)
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()  # clears it
        return self

    def __exit__(self, *exc):
        dr.set_flag(dr.JitFlag.KernelHistory, self.was)


def _kernels() -> tuple[int, int, float]:
    """Kernels launched since the last call: count, how many were compiled
    (not found in the cache), and their compile time in seconds."""
    kernels = [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]
    compiled = [k for k in kernels if not k.get("cache_hit", False) and not k.get("cache_disk", False)]
    seconds = sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in compiled) / 1000.0
    return len(kernels), len(compiled), round(seconds, 4)


def _rates(problem: RefineProblem, schedule: RefineSchedule, iteration: int) -> dict:
    """Each variable's learning rate at ``iteration`` (:meth:`RefineSchedule.rate`)."""
    return {name: schedule.rate(name, iteration, problem.pixels.get(name.rsplit(".", 1)[0]))
            for name in problem.variables}


def _optimizer(problem: RefineProblem, schedule: RefineSchedule):
    opt = mi.ad.Adam(lr=schedule.learning_rate)
    for name, value in problem.variables.items():
        if name == ALBEDO or np.ndim(value) == 3:  # the albedo correction, an environment map
            opt[name] = mi.TensorXf(np.ascontiguousarray(value, np.float32))
        elif name == LIGHT_GAIN:
            opt[name] = mi.Float(np.asarray(value, np.float32))
        else:
            opt[name] = mi.Float(value)
    opt.set_learning_rate(_rates(problem, schedule, 0))
    return opt


def refine_estimate(estimate: BRDFEstimate, capture, shapes, face_model, schedule: RefineSchedule | None = None, *,
                    lamp_radius: float | None = None, measurements=None, seed: int = 0, progress: bool = True,
                    callback=None) -> BRDFEstimate:
    """Refine a texture-space fit by differentiable rendering against the photographs.

    Parameters
    ----------
    estimate : BRDFEstimate
        The fit of :func:`mifaces.reflectance.estimate.fit_brdf` to start from.
    capture : Capture
    shapes : mapping
        Measurement name -> (V, 3) world vertices (mm) of ``face_model``.
    face_model : MorphableModel
    schedule : RefineSchedule, optional
    lamp_radius : float, optional
        Radius (mm) of the lamp, a sphere of that size in place of each point
        light; default the capture's ``metadata["lamp_radius_mm"]``, else a
        point light.
    measurements : sequence of str, optional
        Photographs to refine on (default: those the estimate was fitted to).
    seed : int
        Monte Carlo seeds derive from it.
    progress : bool
    callback : callable, optional
        Called after each step as ``callback(iteration, seconds, estimate)``,
        ``seconds`` since the start, ``estimate()`` giving the estimate at
        that step (the running average of the iterates once ``schedule.average``
        starts; for error-against-time curves).

    Returns
    -------
    BRDFEstimate
        With the refined glossy parameters per region seen by enough pixels
        (and the albedo with ``schedule.albedo_learning_rate``), the average
        of the last iterates (``schedule.average``), if that lowers the loss
        on the held-out pixels (:attr:`RefineSchedule.holdout`); otherwise
        ``estimate`` unchanged. Either way ``refinement``: ``accepted`` and
        ``reason``, the schedule, the loss on the fitted and on the held-out
        pixels before and after, the loss per iteration, the regions refined,
        times and kernel launches.
    """
    schedule = schedule or RefineSchedule()
    if lamp_radius is None:
        lamp_radius = capture.metadata.get(LAMP_RADIUS_KEY)
    t0 = time.perf_counter()
    problem = RefineProblem(estimate, capture, shapes, face_model, schedule, lamp_radius, measurements, seed)
    opt = _optimizer(problem, schedule)
    t_build = time.perf_counter()
    with dr.suspend_grad():
        start = {k: mi.TensorXf(opt[k]) if isinstance(opt[k], mi.TensorXf) else mi.Float(opt[k])
                 for k in problem.variables}
    # the texture-space fit's loss, which the result must beat on held-out pixels (also where it restarted)
    before = problem.total_loss({**start, **{k: mi.Float(v) for k, v in problem.fitted.items()}},
                                schedule.evaluation_spp, seed=seed * 7919 + (1 << 20))
    t_before = time.perf_counter()
    history, average = [], IterateAverage(problem.variables, schedule)
    bar = progress_bar(range(schedule.iterations), desc="refining", unit="it", enabled=progress)
    with _kernel_history():
        for it in bar:
            t = time.perf_counter()
            photo = problem.photographs[it % len(problem.photographs)]
            loss = problem.loss(photo, opt, schedule.spp, seed=seed * 7919 + 2 * it)
            dr.backward(loss)
            opt.step()
            opt.set_learning_rate(_rates(problem, schedule, it + 1))
            dr.eval()
            average.add(it, opt)
            history.append([round(time.perf_counter() - t, 4), photo.name, float(loss[0]), *_kernels()])
            bar.set_postfix_str(f"loss {float(loss[0]):.4g}")
            if callback is not None:
                callback(it + 1, time.perf_counter() - t0, lambda: problem.estimate_of(average.mean(opt), None))
    t_iterate = time.perf_counter()
    result = average.mean(opt)
    after = problem.total_loss(result, schedule.evaluation_spp, seed=seed * 7919 + (1 << 20))
    accepted = after["heldout"] < before["heldout"]
    reason = (f"held-out loss {before['heldout']:.5g} -> {after['heldout']:.5g}: "
              + ("fell, the refined estimate is kept" if accepted else "did not fall, the texture-space fit is kept"))
    t_end = time.perf_counter()
    first = len(problem.photographs)  # the first pass over the photographs compiles the kernels
    refinement = {
        "method": "prb",
        "schedule": dataclasses.asdict(schedule),
        "lamp_radius_mm": float(lamp_radius) if lamp_radius else None, "lights": sorted(problem.light_kinds),
        "photographs": [p.name for p in problem.photographs],
        "regions": sorted(problem.spaces), "region_pixels": problem.pixels,
        "restarted": bool(problem.restarted),
        "light_gains": problem.light_gains(result if accepted else start),
        # the refined maps, where the refinement is kept (else the capture's estimates stand)
        "environment_maps": {light: m.tolist() for light, m in problem.environment_maps(result).items()}
        if accepted else {},
        "accepted": bool(accepted), "reason": reason,
        "loss_before": before["fit"], "loss_after": after["fit"],
        "heldout_loss_before": before["heldout"], "heldout_loss_after": after["heldout"],
        "iterates_averaged": average.count,
        "history_keys": ["seconds", "photograph", "loss", "launches", "compiled", "compile_seconds"],
        "history": history,
        "launches_per_iteration": float(np.mean([h[3] for h in history])),
        "kernels_compiled": {"first_pass": int(sum(h[4] for h in history[:first])),
                             "later": int(sum(h[4] for h in history[first:]))},
        "seconds": {"build": t_build - t0, "loss_before": t_before - t_build, "iterations": t_iterate - t_before,
                    "compile": float(sum(h[5] for h in history)),
                    "first_pass": float(sum(h[0] for h in history[:first])),
                    "per_iteration_after_first_pass": float(np.mean([h[0] for h in history[first:]]))
                    if len(history) > first else None,
                    "loss_after": t_end - t_iterate, "total": t_end - t0},
    }
    refined = (dataclasses.replace(estimate, refinement=refinement) if not accepted
               else problem.estimate_of(result, refinement))
    # the fit's time with its refinement's, as the estimate's total
    refined.seconds = {**estimate.seconds, "total": estimate.seconds.get("total", 0.0) + t_end - t0}
    return refined


__all__ = ["LAMP_RADIUS_KEY", "RefineSchedule", "RefineProblem", "PhotographView", "image_loss", "coverage",
           "mask_weight", "photograph_view", "refine_estimate"]
