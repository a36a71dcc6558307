"""How :func:`mifaces.studio.simulate.simulate` simulates a capture: :class:`SimulationOptions`, one
value from ``mifaces simulate``'s flags (or a script) to the simulator: the subject and its true BRDF,
the session (measurements, lights, cameras), the photographs (size, samples) and the seed."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from .. import brdf as brdf_models
from ..brdf import BUILTIN_NAMES, NAMES as BRDF_MODELS
from ..io.image_files import MAX_IMAGE_SIDE, check_image_size
from ..options.fields import check, option
from ..render import check_render_size
from .environment_light import ENVIRONMENTS, check_environment
from .scene import RIG_YAWS

PRESETS = {"paper": {"measurements": 22}}
#: Most measurements one simulated capture holds.
MAX_MEASUREMENTS = 300
COMPANIONS = ("diffuse", "exposures", "both")


@dataclass(frozen=True, eq=False)
class SimulationOptions:
    """Options of a simulated capture (:func:`mifaces.studio.simulate.simulate`).

    Validated on construction: a value out of its range, an unknown BRDF, preset, companion or
    environment, or sizes beyond what mifaces renders raise a ``ValueError`` naming it (before
    anything is allocated). Whether the truth's BRDF takes ``varying`` or ``subsurface``, and the
    overrides of ``brdf_params``, are checked where the truth is made.

    Attributes
    ----------
    face_model : str, path or MorphableModel
        ``'builtin'``, a model file for :func:`mifaces.load_model` (a path is taken as its string),
        or a model.
    brdf : str
        Ground-truth plugin: ``'cooktorrance'`` (default), ``'phong'``, ``'ward'``, ``'lafortune'``,
        or a Mitsuba built-in outside the fitted families: ``'roughplastic'``, ``'principled'``
        (:mod:`mifaces.brdf.builtin`, defaults mapped from the same published skin values).
    brdf_params : dict, optional
        Overrides in the ``brdf.json`` layout (``{"model", "regions": {region: {param: value}}}``),
        with the plugin's (or built-in's) parameter names
        (:func:`mifaces.studio.truth.brdf_with_overrides`).
    varying : bool
        A spatially varying truth: per-texel lobe scale and width maps
        (oily T-zone, drier cheeks), for ``brdf`` in
        :data:`mifaces.studio.varying.VARYING`; ``ground_truth/maps/``.
    detail : bool
        Add fine geometry the face model cannot express (wrinkles, pores,
        asymmetry) to the face; the ground truth's vertices are the detailed ones.
    subsurface : bool
        Translucent skin: the skin regions as a rough dielectric boundary
        over a scattering medium with measured skin coefficients
        (:mod:`mifaces.studio.subsurface`), rendered with Mitsuba's
        volumetric path tracer: much slower, use few pixels and samples.
        Needs the Cook–Torrance truth (the boundary's reflection).
    measurements : int
        Number of measurements K: ceil(K / 3) light conditions with up to three poses each
        (under an ``environment``: K head turns); at most :data:`MAX_MEASUREMENTS`.
    resolution : (width, height)
        The photographs' size, at least 16 x 16.
    albedo_resolution : int
        Size of the square albedo map.
    seed : int
        Identity, albedo detail, lights, poses, expressions, noise and Monte Carlo
        seeds all derive from it: a fixed seed reproduces the capture.
    preset : {'paper'}, optional
        ``'paper'``: the paper's 22 measurements (8 lights, 3 poses each for 6, 2 for 2); it sets
        ``measurements``.
    spp : int
        Samples per pixel of the point-light renders (companions use half).
    companion : {'diffuse', 'exposures', 'both'}
        Diffuse-light picture (8-bit sRGB), exposure series (three 8-bit sRGB
        pictures at 1/4, 1 and 4 times the point-light exposure), or both.
    environment : {'studio', 'sky'}, optional
        Light every photograph by an environment instead of the point lights
        (:data:`mifaces.studio.environment_light.ENVIRONMENTS`): the generated studio
        (:func:`mifaces.lights.environment.studio_environment`) or Mitsuba's sun and sky with the
        sun at :data:`mifaces.lights.environment.SKY_SUN_ANGLES` about the camera, baked into a map
        (:func:`mifaces.lights.environment.bake_environment`). The capture states that map as its one
        given environment light (``lights/<name>.exr``, pixel value, the frame of
        :func:`mifaces.lights.environment.environment_emitter`), the photographs are rendered with
        exactly it; no steel spheres, no point lights, no white target; each measurement
        its own head turn (:func:`mifaces.studio.scene.head_turns`).
    cameras : int
        Calibrated cameras photographing every shot (:func:`mifaces.studio.scene.rig_cameras`: the
        studio camera, then others turned by :data:`mifaces.studio.scene.RIG_YAWS` about the head):
        each measurement is then one photograph per camera, ``m00`` from the first, ``m00_c1``,
        ``m00_c2``, ... from the others, sharing a ``shot`` (one head pose). The steel spheres and
        the lights' calibration use the first camera.
    """

    face_model: object = option("builtin", help="Face model: 'builtin' or a model file (see mifaces.load_model).")
    brdf: str = option("cooktorrance", choices=BRDF_MODELS + BUILTIN_NAMES,
                       help="Ground-truth BRDF: a fitted family's plugin, or a Mitsuba built-in outside them.")
    brdf_params: dict | None = option(None, form="json",
                                      help='JSON overrides: {"model": ..., "regions": {region: {parameter: value}}} '
                                           '(docs/capture.md).')
    varying: bool = option(False, form="flag",
                           help="Spatially varying truth: per-texel specular scale and roughness maps (oily T-zone, "
                                "drier cheeks).")
    detail: bool = option(False, form="flag",
                          help="Add wrinkles, pores and asymmetry the face model cannot express to the simulated face.")
    subsurface: bool = option(False, form="flag",
                              help="Translucent skin: a rough dielectric boundary over a scattering medium (volumetric "
                                   "path tracer: slow, use a small --resolution and --spp).")
    measurements: int = option(6, bounds=(1, None), help="Number of measurements (three poses per light).")
    resolution: tuple = option((512, 512), form="WxH", help="Image size WxH.")
    albedo_resolution: int = option(1024, bounds=(16, MAX_IMAGE_SIDE))
    seed: int = option(0, bounds=(0, None), help="Seed of everything random.")
    preset: str | None = option(None, choices=(None, *sorted(PRESETS)),
                                help="'paper': the paper's 22 measurements (overrides --measurements).")
    spp: int = option(64, bounds=(1, None), help="Samples per pixel.")
    companion: str = option("diffuse", choices=COMPANIONS, help="Companion of each point-light photograph.")
    environment: str | None = option(None, choices=(*ENVIRONMENTS, None),
                                     help="Light every photograph by the generated studio or the sun and sky instead "
                                          "of the point lights: the capture states the map as its one environment "
                                          "light; each measurement a head turn.")
    cameras: int = option(1, bounds=(1, len(RIG_YAWS)),
                          help="Calibrated cameras photographing every shot (the studio camera, then others turned "
                               f"{', '.join(f'{y:g}' for y in RIG_YAWS[1:])} degrees about the head).")

    def __post_init__(self):
        if isinstance(self.face_model, os.PathLike):
            object.__setattr__(self, "face_model", os.fspath(self.face_model))
        measurements, resolution = _sizes(self)
        object.__setattr__(self, "measurements", measurements)
        object.__setattr__(self, "resolution", resolution)
        check_environment(self.environment)
        object.__setattr__(self, "cameras", _integer("cameras", self.cameras, 1, len(RIG_YAWS)))
        brdf_models.bsdf(self.brdf)  # a ValueError names an unknown model
        check(self)


def _integer(name: str, value, lowest: int, highest: int) -> int:
    """``value`` if it is an integer (not a bool) in [lowest, highest]; a ValueError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lowest <= value <= highest:
        raise ValueError(f"{name} must be an integer from {lowest} to {highest}, got {value!r}")
    return int(value)


def _sizes(options: SimulationOptions) -> tuple[int, tuple[int, int]]:
    """The number of measurements (the preset's, if one is given) and the resolution; a ValueError
    naming a bad option (sizes within :func:`mifaces.render.check_render_size`'s limits, before
    anything is allocated)."""
    measurements, preset = options.measurements, options.preset
    if preset is not None:
        if preset not in PRESETS:
            raise ValueError(f"unknown preset {preset!r}; presets: {sorted(PRESETS)}")
        measurements = PRESETS[preset]["measurements"]
    if isinstance(measurements, (int, np.integer)) and not isinstance(measurements, bool) and measurements < 1:
        raise ValueError(f"measurements must be >= 1, got {measurements}")
    measurements = _integer("measurements", measurements, 1, MAX_MEASUREMENTS)
    if options.companion not in COMPANIONS:
        raise ValueError(f"companion must be 'diffuse', 'exposures' or 'both', got {options.companion!r}")
    try:
        width, height = (_integer("resolution", r, 1, 2 ** 31 - 1) for r in options.resolution)
    except TypeError:
        raise ValueError(f"resolution must be (width, height), got {options.resolution!r}") from None
    if width < 16 or height < 16:
        raise ValueError(f"resolution must be at least 16x16, got {width}x{height}")
    check_render_size(width, height, _integer("spp", options.spp, 1, 1 << 20), "simulate")
    check_image_size(_integer("albedo_resolution", options.albedo_resolution, 16, MAX_IMAGE_SIDE),
                     options.albedo_resolution, "albedo map")
    _integer("seed", options.seed, 0, 2 ** 32 - 1)
    return measurements, (width, height)


__all__ = ["SimulationOptions", "PRESETS", "COMPANIONS", "MAX_MEASUREMENTS"]
