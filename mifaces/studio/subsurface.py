"""A subsurface ground truth: skin as a rough dielectric boundary over a
homogeneous scattering medium.

Real skin is translucent: light enters, scatters in the dermis and leaves
millimetres away, which blurs shading and reddens shadow edges. The
paper's BRDF model (and every fitted family) ignores it. This truth
renders the skin regions (skin, lips, nostrils, beard) as

* a boundary with skin's surface reflection: the ``skinboundary`` plugin
  (:mod:`mifaces.plugins.boundary`), Cook–Torrance with each region's
  published roughness, η and scale (:data:`mifaces.studio.truth.COOK_TORRANCE_REGIONS`),
  transmitting the rest (1 - F) without refraction;
* inside it, a homogeneous medium with isotropic scattering and the
  measured skin coefficients of Jensen, Marschner, Levoy & Hanrahan, "A
  Practical Model for Subsurface Light Transport", SIGGRAPH 2001 (their
  table of measured scattering and absorption coefficients), "Skin1": reduced scattering
  σs' = (0.74, 0.88, 1.01) mm⁻¹ and absorption σa = (0.032, 0.17, 0.48) mm⁻¹
  (RGB). Scene units are mm, so they are used as they are.

The eyes, eyebrows and hair stay opaque surfaces (their Cook–Torrance truth
over the albedo map). Rendering is Mitsuba's volumetric path tracer
(``volpath``, :data:`INTEGRATOR`): several hundred scattering events per
path, so it is far slower than the surface truths; use a small resolution
and few samples on a CPU.

The ground truth's albedo map gives the skin regions the diffuse
reflectance the medium has by the dipole model (:func:`dipole_albedo`,
Jensen et al. 2001, with their fit of the diffuse Fresnel reflectance Fdr): what a BRDF fit that ignores
translucency should find at best. The boundary lets light out without
total internal reflection, so the rendered skin is somewhat brighter than
the dipole predicts; the albedo "bias" measured against this map includes
that.
"""

from __future__ import annotations

import numpy as np

from ..model.regions import REGIONS, region_entry
from .varying import texel_regions

#: Jensen et al. 2001, measured "Skin1": reduced scattering and absorption coefficients, mm⁻¹ (RGB).
SKIN1 = {"sigma_s_reduced": (0.74, 0.88, 1.01), "sigma_a": (0.032, 0.17, 0.48)}
#: Regions rendered as translucent skin; the others keep their opaque surface truth.
TRANSLUCENT = ("skin", "lips", "nostrils", "beard")
#: The volumetric path tracer of the subsurface photographs.
INTEGRATOR = {"type": "volpath", "max_depth": 256, "hide_emitters": False}
#: The source of :data:`SKIN1`.
SOURCE = ("Jensen, Marschner, Levoy & Hanrahan, A Practical Model for Subsurface Light Transport, "
          "SIGGRAPH 2001, measured parameters (Skin1)")


def medium(coefficients: dict = SKIN1) -> dict:
    """The homogeneous medium (Mitsuba dict) of ``coefficients``: isotropic
    phase function with the reduced scattering coefficient, per RGB channel
    the single-scattering albedo α' = σs'/σt' (σt' = σs' + σa), and one
    extinction for all channels, the mean of σt' (:func:`extinction`).

    The common extinction keeps each channel's α', hence its diffuse
    reflectance (which depends on α' alone, :func:`dipole_albedo`), and
    scales its diffusion length 1/√(3 σa σt') by √(σt'/mean σt') (0.84,
    0.98, 1.16 for Skin1); with per-channel extinctions the volumetric path
    tracer's spectral sampling is far noisier at the same samples per pixel
    (fireflies 70 times the face's brightness at 32 spp, measured on the
    built-in face at 128²)."""
    ss, sa = (np.asarray(coefficients[k], np.float64) for k in ("sigma_s_reduced", "sigma_a"))
    return {"type": "homogeneous", "albedo": {"type": "rgb", "value": (ss / (ss + sa)).tolist()},
            "sigma_t": extinction(coefficients), "phase": {"type": "isotropic"}}


def extinction(coefficients: dict = SKIN1) -> float:
    """The medium's extinction, mm⁻¹: the mean over RGB of σt' = σs' + σa."""
    return float(np.mean(np.add(coefficients["sigma_s_reduced"], coefficients["sigma_a"])))


def dipole_albedo(coefficients: dict = SKIN1, eta: float = 1.38) -> np.ndarray:
    """Total diffuse reflectance Rd (RGB) of a semi-infinite medium by the
    dipole model (Jensen et al. 2001): Rd = (α'/2)(1 + e^(-4/3 A √(3(1-α'))))
    e^(-√(3(1-α'))), α' = σs'/σt', A = (1 + Fdr)/(1 - Fdr),
    Fdr = -1.440/η² + 0.710/η + 0.668 + 0.0636 η."""
    ss, sa = (np.asarray(coefficients[k], np.float64) for k in ("sigma_s_reduced", "sigma_a"))
    alpha = ss / (ss + sa)
    fdr = -1.440 / eta ** 2 + 0.710 / eta + 0.668 + 0.0636 * eta
    a = (1 + fdr) / (1 - fdr)
    root = np.sqrt(3 * (1 - alpha))
    return alpha / 2 * (1 + np.exp(-4 / 3 * a * root)) * np.exp(-root)


def boundary_bsdf(truth: dict, region: str) -> dict:
    """The ``skinboundary`` BSDF (Mitsuba dict) of ``region`` of the Cook–Torrance ``truth``."""
    params = region_entry(truth["regions"], region)
    return {"type": "skinboundary", "specular_reflectance": {"type": "rgb", "value": list(
        np.broadcast_to(np.asarray(params["specular_reflectance"], np.float64), 3).tolist())},
        "roughness": float(params["roughness"]), "eta": float(params["eta"])}


def subsurface_albedo(face_model, albedo: np.ndarray, truth: dict) -> np.ndarray:
    """The albedo map with the translucent regions' texels at their dipole albedo (:func:`dipole_albedo`)."""
    labels = texel_regions(face_model, albedo.shape[0])
    out = np.array(albedo, np.float32)
    for region in TRANSLUCENT:
        eta = float(region_entry(truth["regions"], region)["eta"])
        out[labels == REGIONS[region]] = dipole_albedo(SKIN1, eta).astype(np.float32)
    return out


def subsurface_meshes(region_meshes: dict, truth: dict, surface_bsdf) -> dict:
    """Mitsuba meshes of a face's ``region_meshes``
    (:func:`mifaces.render.region_meshes`): the translucent regions as the
    boundary over the skin medium, the others with ``surface_bsdf(region)``."""
    inside = medium()
    return {key: part.mesh(boundary_bsdf(truth, part.region), interior=inside) if part.region in TRANSLUCENT
            else part.mesh(surface_bsdf(part.region)) for key, part in region_meshes.items()}


def description(truth: dict) -> dict:
    """What the subsurface truth was, for the ground truth's ``scene.json``."""
    eta = float(truth["regions"]["skin"]["eta"])
    return {"medium": {k: list(v) for k, v in SKIN1.items()}, "source": SOURCE, "regions": list(TRANSLUCENT),
            "extinction_per_mm": round(extinction(SKIN1), 5),
            "dipole_albedo_skin": [round(float(x), 5) for x in dipole_albedo(SKIN1, eta)],
            "integrator": INTEGRATOR}
