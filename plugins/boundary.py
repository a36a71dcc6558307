"""The rough dielectric boundary of a scattering medium, index-matched inside
(``<bsdf type="skinboundary">``): skin's surface over its subsurface.

Outside (both directions above the surface) it reflects a Cook–Torrance
lobe: Beckmann roughness ``roughness`` (RMS slope m), dielectric Fresnel at
``eta``, scale ``specular_reflectance`` (:mod:`mifaces.brdf.cooktorrance`,
the same functions the fits call). The rest of the light goes straight
through, weighted by 1 - F(|cos θ|, η) (a ``null`` transmission): inside,
a homogeneous medium (the shape's ``interior``) scatters it, and on its
way out it is transmitted with the same weight or mirror-reflected back in
with probability F.

The transmission keeps the direction (no refraction): Mitsuba's volumetric
path tracer (``volpath``) then connects scattering events inside the
medium to the lights through the boundary (``eval_null_transmission``);
through a refracting ``dielectric`` or ``roughdielectric`` boundary a point
light could never be reached from inside. Inside a diffusing medium, a few
mean free paths randomize the direction anyway; what is lost is total
internal reflection beyond the critical angle (the Fresnel weight is taken
at the outside angle), so light leaves the medium somewhat more easily than
through a refracting boundary.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mifaces.brdf.cooktorrance import CookTorrance
from mifaces.brdf.microfacet import fresnel_dielectric

#: Parameter name -> default.
DEFAULTS = {"specular_reflectance": 1.0, "roughness": 0.35, "eta": 1.38}


class SkinBoundary:
    """The plugin's behaviour; :func:`mifaces.plugins.plugin_class` builds the
    registered class on the variant's ``mi.BSDF`` (as for the analytic plugins)."""

    def __init__(self, props: mi.Properties):
        mi.BSDF.__init__(self, props)
        self.model = CookTorrance()
        self.params = {}
        for name, default in DEFAULTS.items():
            value = props.get(name, default)
            self.model.parameter(name).check(value, "skinboundary BSDF")
            self.params[name] = mi.Color3f(value) if name == "specular_reflectance" else mi.Float(value)
        self.params["diffuse_reflectance"] = mi.Color3f(0.0)
        glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        null = mi.BSDFFlags.Null | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
        mirror = mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.BackSide
        self.m_components = [int(glossy), int(null), int(mirror)]
        self.m_flags = int(glossy) | int(null) | int(mirror)

    def traverse(self, callback):
        for name in DEFAULTS:
            callback.put(name, self.params[name], mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=None):
        for value in self.params.values():
            dr.make_opaque(value)

    def _fresnel(self, si):
        return fresnel_dielectric(dr.abs(mi.Frame3f.cos_theta(si.wi)), self.params["eta"])

    def eval_null_transmission(self, si, active=True):
        return mi.Color3f(dr.select(active, 1.0 - self._fresnel(si), 0.0))

    def _glossy(self, wi, wo):
        f = self.model.eval(wi, wo, self.params, diffuse=False) * dr.maximum(wo.z, 0.0)
        return dr.select((wi.z > 0) & (wo.z > 0), f, 0.0)

    def eval(self, ctx, si, wo, active=True):
        if not ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0):
            return mi.Color3f(0.0)
        return dr.select(active, self._glossy(si.wi, wo), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        outside = si.wi.z > 0
        p = self.model.pdf_specular(si.wi, wo, self.params) * self._fresnel(si)
        return dr.select(active & outside & (wo.z > 0), p, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        wi = si.wi
        outside = wi.z > 0
        fresnel = self._fresnel(si)
        # outside: the glossy lobe with probability F, else straight through;
        # inside: the mirror with probability F, else straight through
        reflect = sample1 < fresnel
        bs = dr.zeros(mi.BSDFSample3f)
        glossy_wo = self.model.sample_specular(wi, sample1 / dr.maximum(fresnel, 1e-6), sample2, self.params)
        mirror_wo = mi.reflect(wi)
        wo = dr.select(reflect, dr.select(outside, glossy_wo, mirror_wo), -wi)
        glossy_pdf = self.model.pdf_specular(wi, wo, self.params) * fresnel
        glossy = reflect & outside
        bs.wo = wo
        bs.eta = 1.0
        bs.pdf = dr.select(glossy, glossy_pdf, dr.select(reflect, fresnel, 1.0 - fresnel))
        bs.sampled_type = dr.select(glossy, mi.UInt32(+mi.BSDFFlags.GlossyReflection),
                                    dr.select(reflect, mi.UInt32(+mi.BSDFFlags.DeltaReflection),
                                              mi.UInt32(+mi.BSDFFlags.Null)))
        bs.sampled_component = dr.select(glossy, mi.UInt32(0), dr.select(reflect, mi.UInt32(2), mi.UInt32(1)))
        weight = dr.select(glossy, self._glossy(wi, wo) / dr.maximum(glossy_pdf, 1e-30), 1.0)
        valid = active & dr.select(glossy, (wo.z > 0) & (glossy_pdf > 0), True)
        bs.pdf = dr.select(valid, bs.pdf, 0.0)
        return bs, mi.Color3f(dr.select(valid, weight, 0.0))

    def to_string(self):
        return f"SkinBoundary[{', '.join(f'{k}={self.params[k]}' for k in DEFAULTS)}]"
