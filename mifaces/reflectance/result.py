"""The BRDF fit's result, :class:`BRDFEstimate`: the region fits, the per-texel maps, how they
were fitted, and the ``brdf.json`` document (:mod:`.io` writes and reads the files)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..model.regions import REGIONS
from ..render.blend import BLEND_KEY, BLEND_MM
from .fit.region_fit import RegionFit
from .maps.diffuse import DiffuseMap
from .maps.normals import encode
from .maps.specular import SpecularMap
from .options import FitOptions

def fitted_light(light, refinement: dict | None):
    """``light`` (:class:`~mifaces.capture.Light`) as a fit was fitted under it: an estimated
    environment map that the fit's refinement refined (``refinement['environment_maps']``, a
    ``brdf.json`` record, kept only where the refinement was) is that refined map; any other light
    is itself."""
    maps = (refinement or {}).get("environment_maps") or {}
    return light.with_estimated_map(maps.get(light.name))


#: The fitted BRDF's files in an output folder.
FILES = {"brdf": "brdf.json", "albedo": "albedo.exr", "preview": "albedo.png", "scene": "scene.xml",
         "normals": "normals.exr", "specular": "specular.exr", "albedo_std": "albedo_std.exr",
         "environment": "environment.exr"}
#: Fit statistics stored per region under ``brdf.json``'s ``"fit"``.
FIT_KEYS = ("diffuse_reflectance", "loss", "samples", "seconds", "status", "reason", "iterations")


@dataclass
class BRDFEstimate:
    """Fitted BRDFs of one capture.

    Attributes
    ----------
    model : str
        Plugin name (``phong``, ``cooktorrance``, ``ward``, ``lafortune``).
    options : dict
        The model's options (e.g. ``{"lobes": 2}`` for Lafortune).
    fits : dict
        Region name -> :class:`~mifaces.reflectance.fit.region_fit.RegionFit`.
    albedo : DiffuseMap
        Per-texel diffuse albedo after refinement (sec. 5.3).
    region_map : (R, R) uint8
        Region label per texel of the albedo map.
    samples : int
        Reflectance samples used.
    measurements : tuple of str
    seconds : dict
        Wall time of each step: ``samples``, ``fit`` (the region fits), ``refine`` (the per-texel
        maps), ``total`` (with a refinement by differentiable rendering, when there was one).
    refinement : dict or None
        How the fit was refined by differentiable rendering
        (:func:`mifaces.refine.reflectance.refine_estimate`), with its image
        loss before and after; None if it was not.
    normals : ndarray (R, R, 3) or None
        Per-texel unit normals relative to Mitsuba's shading frame of the
        face mesh (:func:`mifaces.reflectance.maps.normals.mitsuba_tangent_normals`),
        if they were estimated (``fit_brdf(..., options=FitOptions(normals=True))``).
    normal_refinement : dict or None
        How they were (:meth:`~mifaces.reflectance.maps.normals.TexelNormals.summary`).
    specular : SpecularMap or None
        Per-texel specular reflectance shrunk towards each region's
        (:func:`mifaces.reflectance.maps.specular.refine_specular`), if estimated.
    lighting : dict or None
        How the lights were known where they were estimated from the photographs
        (:mod:`mifaces.light_estimation.unknown`): ``{"lights": "estimated", "reflectance": "relative", "note"}``,
        written to ``brdf.json``; None for a capture whose lights are given.
    light_balance : dict or None
        Light name -> the factor its given intensity was off by, as the face's one albedo
        says (``fit_brdf(..., options=FitOptions(balance_lights=True))``,
        :func:`mifaces.reflectance.light_balance.balance_given_lights`); None where not balanced.
    interreflection : dict or None
        How the light bounced off the face was taken out of the samples
        (``FitOptions(interreflection=True)``, :mod:`mifaces.reflectance.interreflection`: the
        renders' depth, width and samples per pixel, the seconds it took); None where it was not.
    texel_albedo : bool
        Whether the glossy parts were fitted with an albedo per texel
        (``FitOptions(texel_albedo=True)``, the default); ``brdf.json`` says which (``"texel_albedo"``).
    fit_options : FitOptions or None
        The options the fit was asked to run with; ``brdf.json``'s ``"fit_options"`` records them
        whole, ``requested`` and ``effective`` (:meth:`effective_options`).
    """

    model: str
    options: dict
    fits: dict[str, RegionFit]
    albedo: DiffuseMap
    region_map: np.ndarray
    samples: int
    measurements: tuple[str, ...]
    seconds: dict = field(default_factory=dict)
    refinement: dict | None = None
    normals: np.ndarray | None = None
    normal_refinement: dict | None = None
    specular: SpecularMap | None = None
    lighting: dict | None = None
    light_balance: dict | None = None
    interreflection: dict | None = None
    texel_albedo: bool = False
    fit_options: FitOptions | None = None

    def effective_options(self) -> FitOptions | None:
        """The options as the fit ran: :attr:`fit_options` as its plan resolved them
        (:meth:`FitOptions.resolved <mifaces.reflectance.options.FitOptions.resolved>`), less what
        the data did not allow: the per-texel albedo where it measured no lobe on skin, normals
        where no texel had the samples, specular maps for a model without a specular reflectance."""
        if self.fit_options is None:
            return None
        ran = dataclasses.replace(self.fit_options, normals=self.fit_options.normals and self.normals is not None)
        return dataclasses.replace(ran.resolved(), texel_albedo=bool(self.texel_albedo),
                                   specular_maps=self.specular is not None)

    def fitted_light(self, light):
        """``light`` as this estimate was fitted under it (:func:`fitted_light`)."""
        return fitted_light(light, self.refinement)

    def normal_texture(self) -> np.ndarray | None:
        """The normals as a ``normalmap`` texture ((n + 1) / 2), or None."""
        return None if self.normals is None else encode(self.normals)

    def specular_texture(self) -> np.ndarray | None:
        """The per-texel specular reflectance (R, R, 3) that renders read, or None."""
        return None if self.specular is None else self.specular.specular

    @property
    def resolution(self) -> int:
        return int(self.region_map.shape[0])

    def regions(self) -> dict[str, dict]:
        """Region -> the plugin's glossy parameters (no diffuse: that is the albedo map)."""
        return {name: {k: v for k, v in fit.params.items() if k != "diffuse_reflectance"}
                for name, fit in self.fits.items()}

    def to_json(self) -> dict:
        """The ``brdf.json`` document."""
        options = {k: v for k, v in self.options.items()}
        return {"model": self.model, "options": options, "regions": self.regions(),
                "fit": {name: {k: (fit.params.get(k) if k == "diffuse_reflectance" else getattr(fit, k))
                               for k in FIT_KEYS} for name, fit in self.fits.items()},
                "samples": int(self.samples), "resolution": self.resolution,
                "measurements": list(self.measurements), "seconds": {k: round(v, 3) for k, v in self.seconds.items()},
                "albedo": FILES["albedo"], "refinement": self.refinement, BLEND_KEY: BLEND_MM,
                "uncertainty": {name: fit.uncertainty for name, fit in self.fits.items()},
                **({} if self.albedo.std is None else {"albedo_std": FILES["albedo_std"]}),
                **({} if self.lighting is None else {"lighting": self.lighting}),
                **({} if self.light_balance is None else {"light_balance": self.light_balance}),
                **({} if self.interreflection is None else {"interreflection": self.interreflection}),
                "texel_albedo": bool(self.texel_albedo),
                **({} if self.fit_options is None else {"fit_options": {
                    "requested": self.fit_options.to_record(), "effective": self.effective_options().to_record()}}),
                **({} if self.normals is None else {"normals": FILES["normals"],
                                                    "normal_refinement": self.normal_refinement}),
                **({} if self.specular is None else {"specular": FILES["specular"], "specular_shrinkage": {
                    name: self.specular.shrinkage.get(REGIONS[name]) for name in self.fits}})}


__all__ = ["FILES", "FIT_KEYS", "BRDFEstimate", "fitted_light"]
