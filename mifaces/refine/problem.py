"""The refinement's problem (:mod:`mifaces.refine.reflectance`): the photographs of a capture
as differentiable renders of the fitted face (:func:`~mifaces.refine.photograph.photograph_view`),
the unconstrained variables (each region's glossy parameters, the albedo correction, the lights'
gains, estimated environment maps) and the loss E over them."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import brdf as brdf_models
from ..model.regions import FALLBACK_REGION, REGIONS
from ..render import FaceScene
from ..render.blend import hard_borders
from ..reflectance.fit.parameters import ParameterSpace
from ..reflectance.result import BRDFEstimate
from .albedo_correction import AlbedoCorrection
from .environment import EnvironmentVariable, padded_envmap
from .photograph import Appearance, RenderSettings, image_loss, mask_weight, photograph_view
from .schedule import ALBEDO, LIGHT_GAIN, RefineSchedule, environment_variable, holdout_pixels

#: Fewest pixels (over all photographs, at the render resolution) for a region's parameters to be variables.
MIN_PIXELS = 40


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
        # each region's values up to its border: the variables are the regions' values
        appearance = Appearance(hard_borders(estimate.to_json()), estimate.albedo.albedo)
        names = list(measurements or estimate.measurements)
        scale = capture.reflectance_scale() / np.pi
        self.light_kinds = set()
        self.photographs = [self._photograph(capture, m, shapes[m.name], face_model, appearance, scale,
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
                          any(capture.light(name).radiance_map is not None for name in self.lights))
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
            self.albedo = AlbedoCorrection(appearance.albedo, schedule.albedo_cell)
            self.variables[ALBEDO] = self.albedo.start()
        if schedule.light_gain_learning_rate is not None and len(self.lights) > 1:
            self.variables[LIGHT_GAIN] = np.zeros(len(self.lights))
        #: estimated environment light -> :class:`~mifaces.refine.environment.EnvironmentVariable`
        self.environments = {}
        if schedule.environment_learning_rate is not None:
            for name in self.lights:
                envmap = capture.light(name).estimated_map
                if envmap is not None:
                    log = EnvironmentVariable.start(envmap)
                    self.environments[name] = EnvironmentVariable.of(log)
                    self.variables[environment_variable(name)] = log

    def _photograph(self, capture, m, vertices, face_model, appearance: Appearance, scale,
                    lamp_radius) -> _Photograph:
        face = FaceScene(face_model, vertices)
        rendering = RenderSettings(self.schedule.downsample, self.schedule.spp, {
            "type": "prb", "max_depth": int(self.schedule.max_depth), "hide_emitters": True})
        view = photograph_view(capture, m, face, appearance, self.estimate.region_map, scale, lamp_radius, rendering)
        self.light_kinds.add(view.light_kind)
        free = {p.name for p in self.model.specular_parameters()}
        keys, albedo_keys = {}, []
        for key in view.params.keys():
            region, parameter = face.region_of_key(key) or (None, "")
            name = parameter.split(".")[0]
            if region is not None and name in free:
                keys[key] = (region, name)
            elif region is not None and parameter == "diffuse_reflectance.data":
                albedo_keys.append(key)
        names = {label: name for name, label in REGIONS.items()}
        pixels = {}
        for label, n in zip(*np.unique(view.labels[view.mask], return_counts=True)):
            region = names.get(int(label), FALLBACK_REGION)
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
        return self.environments[light].radiance(variables[environment_variable(light)])

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


__all__ = ["MIN_PIXELS", "RefineProblem"]
