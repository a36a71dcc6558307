"""A Mitsuba BSDF around one of the analytic models of :mod:`mifaces.brdf`.

One generic plugin serves every model: :func:`behaviour` builds it from the
model's class, whose :meth:`~mifaces.brdf.model.BRDFModel.from_properties`
reads the options (and, for Lafortune, the lobes) from the scene, and whose
parameters, formula and sources make the plugin's documentation.

The plugin reads the model's options and parameters from the scene's
properties, exposes every parameter through ``traverse`` (differentiable),
evaluates the model's formulas (the same functions the fitters call) and
samples a mixture of the model's glossy lobe(s) and the cosine-weighted
diffuse lobe. It is one-sided: zero unless both directions are above the
surface (wrap it in ``twosided`` for both sides). ``eval`` returns
f(wi, wo) · cos θo, Mitsuba's convention.

Every parameter may be a texture instead of a value (a spatially varying
BRDF: ``specular_reflectance``, ``roughness``, ... per texel, e.g. a
``bitmap``): an RGB parameter reads the texture's colour, a scalar one its
``eval_1``. A bitmap texture's values are checked against the parameter's
range like a value's.

A part whose weight is zero and not being differentiated (a black
``diffuse_reflectance``, a zero ``specular_reflectance``, a Lafortune lobe
with zero coefficients) is left out: it is not evaluated, not sampled and its
flag is not set.
"""

from __future__ import annotations

import functools
import sys
from typing import ClassVar

import drjit as dr
import mitsuba as mi
import numpy as np

from mifaces.brdf.model import DIFFUSE, BRDFModel, mean


def _texture_is_zero(texture) -> bool:
    """True if the (non-negative) reflectance ``texture`` is black everywhere
    and none of its parameters is being differentiated."""
    if any(dr.grad_enabled(v) for _, v in mi.traverse(texture).items()):
        return False
    return bool(dr.all(texture.mean() == 0, axis=None))


def _texture_range(texture) -> list[float] | None:
    """Smallest and largest value of a texture's data (a bitmap's ``data``,
    a constant's ``value``, a checkerboard's colours), or None where it has no such parameter."""
    values = [dr.detach(v) for k, v in mi.traverse(texture).items() if k.split(".")[-1] in ("data", "value")]
    if not values:
        return None
    data = np.concatenate([np.asarray(v, np.float64).ravel() for v in values])
    return [float(data.min()), float(data.max())]


def _value_is_zero(value) -> bool:
    return not dr.grad_enabled(value) and bool(dr.all(value == 0, axis=None))


def xml_example(model: BRDFModel) -> str:
    """A ``<bsdf>`` element of ``model``, indented for a docstring: every
    parameter at the value a fit starts from (a weak lobe of medium width),
    every option at its default."""
    lines = [f'<bsdf type="{model.name}">']
    for p in model.parameters():
        lines.append(f'    <{p.kind} name="{p.name}" value="{p.default if p.start is None else p.start:g}"/>')
    for key, value in model.default_options().items():
        lines.append(f'    <string name="{key}" value="{value}"/>')
    return "\n".join("    " + line for line in lines + ["</bsdf>"])


def plugin_docstring(cls: type[BRDFModel]) -> str:
    """Plugin documentation of model ``cls``: a summary, the model's formula
    and sources (its module's docstring), a table of its options and
    parameters, and an XML example (of :attr:`~mifaces.brdf.model.BRDFModel.EXAMPLE_OPTIONS`)."""
    model = cls(**cls.EXAMPLE_OPTIONS)
    summary = f"{cls.title} BSDF (``<bsdf type=\"{cls.name}\">``)" + (", one or more lobes." if cls.SEVERAL_LOBES
                                                                     else ".")
    opts = [f"    {k:<22} string one of {', '.join(v)} (default {v[0]})" for k, v in cls.OPTIONS.items()]
    rows = [f"    {p.name:<22} {p.kind:<6} default {p.default:<8g} {p.doc}" for p in model.parameters()]
    formula = sys.modules[cls.__module__].__doc__ or ""
    return (f"{summary}\n\n{formula.strip()}\n\nParameters (XML / mi.traverse names)\n"
            + "\n".join(opts + rows) + f"\n\nExample::\n\n{xml_example(model)}\n")


class AnalyticBSDF:
    """The plugin's behaviour for the model class :attr:`MODEL`, which
    :func:`behaviour` sets.

    Mitsuba's ``BSDF`` base class differs per variant, so this class holds
    the behaviour only; :func:`mifaces.plugins.plugin_class` builds the
    registered class on the current variant's ``mi.BSDF`` from it. Methods
    therefore call base classes explicitly, not through ``super()``.
    """

    MODEL: ClassVar[type[BRDFModel]]

    def __init__(self, props: mi.Properties):
        mi.BSDF.__init__(self, props)
        #: the model as the scene describes it; ``model`` leaves out its zero lobes
        self.full_model = self.MODEL.from_properties(props.keys(), props.get)
        self.model = self.full_model
        self.diffuse = props.get_texture(DIFFUSE.name, DIFFUSE.default)
        self.values, self.textures = {}, {}
        for p in self.model.specular_parameters():
            value = props.get(p.name, p.default)
            where = f"{self.MODEL.name} BSDF {props.id() or ''}".rstrip()
            if isinstance(value, mi.Texture):
                self.textures[p.name] = value
                self._check_texture(p.name)
                continue
            if isinstance(value, mi.Object):
                raise ValueError(f"{type(self).__name__}: parameter {p.name!r} must be a "
                                 f"{'colour' if p.kind == 'rgb' else 'number'} or a texture, not a {type(value).__name__}")
            value = p.check(value, where)
            if p.kind == "rgb":
                self.values[p.name] = mi.Color3f(value)
            else:
                # Scalar variants box numbers so that mi.traverse can update them.
                self.values[p.name] = mi.Float(value) if dr.is_jit_v(mi.Float) else dr.scalar.Array1f(value)
        self.parameters_changed()

    # -- parameters -------------------------------------------------------
    def _check_texture(self, name: str) -> None:
        """Check a parameter texture's values (where it exposes them) against the parameter's range."""
        span = _texture_range(self.textures[name])
        if span is not None:
            parameter = {p.name: p for p in self.full_model.specular_parameters()}[name]
            for value in span:
                parameter.check(value, f"{self.MODEL.name} BSDF texture {name}")

    def traverse(self, callback):
        callback.put(DIFFUSE.name, self.diffuse, mi.ParamFlags.Differentiable)
        for name, value in self.values.items():
            callback.put(name, value, mi.ParamFlags.Differentiable)
        for name, texture in self.textures.items():
            callback.put(name, texture, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=None):
        # values set through mi.traverse are checked as the scene's were
        self.full_model.validate({k: v for k, v in self.values.items() if keys is None or k in keys},
                                 f"{self.MODEL.name} BSDF")
        for name in self.textures:
            if keys is not None and any(k == name or k.startswith(name + ".") for k in keys):
                self._check_texture(name)
        for value in self.values.values():
            dr.make_opaque(value)
        self.has_diffuse = not _texture_is_zero(self.diffuse)
        self.has_specular = self._specular_active()
        components = []
        if self.has_specular:
            components.append(mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide)
        if self.has_diffuse:
            components.append(mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide)
        self.m_components = [int(c) for c in components]
        flags = 0
        for c in components:
            flags |= int(c)
        self.m_flags = flags

    def _specular_active(self) -> bool:
        """Whether the glossy part has non-zero weight; only the lobes with
        a non-zero scale (:meth:`~mifaces.brdf.model.BRDFModel.lobe_scales`)
        are evaluated."""
        def zero(name):
            if name in self.textures:
                return _texture_is_zero(self.textures[name])
            return name in self.values and _value_is_zero(self.values[name])

        active = [j for j, scales in self.full_model.lobe_scales().items() if not all(zero(n) for n in scales)]
        if active:
            self.model = self.full_model.only_lobes(active)
        return bool(active)

    def _component_index(self, part: str) -> int:
        return (0 if part == "specular" else int(self.has_specular))

    def _parts(self, ctx):
        """(diffuse, specular) parts enabled by the scene and by ``ctx``."""
        diffuse = self.has_diffuse and ctx.is_enabled(mi.BSDFFlags.DiffuseReflection,
                                                      self._component_index("diffuse"))
        specular = self.has_specular and ctx.is_enabled(mi.BSDFFlags.GlossyReflection,
                                                        self._component_index("specular"))
        return diffuse, specular

    def _params(self, si, active):
        params = {k: v[0] if isinstance(v, dr.scalar.Array1f) else v for k, v in self.values.items()}
        kinds = {p.name: p.kind for p in self.full_model.specular_parameters()}
        for k, texture in self.textures.items():
            params[k] = texture.eval(si, active) if kinds[k] == "rgb" else texture.eval_1(si, active)
        if self.has_diffuse:
            params[DIFFUSE.name] = self.diffuse.eval(si, active)
        return params

    # -- evaluation and sampling -----------------------------------------
    def _specular_probability(self, wi, params, diffuse, specular):
        if not specular:
            return 0.0
        if not diffuse:
            return 1.0
        ws = dr.maximum(self.model.specular_weight(wi, params), 0.0)
        wd = mean(params[DIFFUSE.name])
        total = ws + wd
        return dr.select(total > 0, ws / dr.maximum(total, 1e-30), 0.5)

    def _eval_pdf(self, wi, wo, params, diffuse, specular):
        f = self.model.eval(wi, wo, params, diffuse=diffuse, specular=specular)
        cos_o = dr.maximum(wo.z, 0.0)
        p_spec = self._specular_probability(wi, params, diffuse, specular)
        pdf = 0.0
        if specular:
            pdf = p_spec * self.model.pdf_specular(wi, wo, params)
        if diffuse:
            pdf = pdf + (1.0 - p_spec) * mi.warp.square_to_cosine_hemisphere_pdf(wo)
        valid = (wi.z > 0) & (wo.z > 0)
        return dr.select(valid, f * cos_o, 0.0), dr.select(valid, pdf, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        diffuse, specular = self._parts(ctx)
        if not (diffuse or specular):
            return mi.Color3f(0.0), mi.Float(0.0)
        f, pdf = self._eval_pdf(si.wi, wo, self._params(si, active), diffuse, specular)
        return dr.select(active, f, 0.0), dr.select(active, pdf, 0.0)

    # What eval or pdf leaves unused, the JIT variants drop from the traced kernel.
    def eval(self, ctx, si, wo, active=True):
        return self.eval_pdf(ctx, si, wo, active)[0]

    def pdf(self, ctx, si, wo, active=True):
        return self.eval_pdf(ctx, si, wo, active)[1]

    def sample(self, ctx, si, sample1, sample2, active=True):
        wi = si.wi
        diffuse, specular = self._parts(ctx)
        bs = dr.zeros(mi.BSDFSample3f)
        if not (diffuse or specular):
            return bs, mi.Color3f(0.0)
        params = self._params(si, active)
        p_spec = self._specular_probability(wi, params, diffuse, specular)
        if specular and diffuse:
            chose_specular = sample1 < p_spec
            u = dr.select(chose_specular, sample1 / dr.maximum(p_spec, 1e-30),
                          (sample1 - p_spec) / dr.maximum(1.0 - p_spec, 1e-30))
            wo = dr.select(chose_specular,
                           self.model.sample_specular(wi, u, sample2, params),
                           mi.warp.square_to_cosine_hemisphere(sample2))
        elif specular:
            chose_specular = True
            wo = self.model.sample_specular(wi, sample1, sample2, params)
        else:
            chose_specular = False
            wo = mi.warp.square_to_cosine_hemisphere(sample2)
        f, pdf = self._eval_pdf(wi, wo, params, diffuse, specular)
        active = active & (wi.z > 0) & (wo.z > 0) & (pdf > 0)
        bs.wo = wo
        bs.pdf = dr.select(active, pdf, 0.0)
        bs.eta = 1.0
        glossy, lambert = mi.UInt32(+mi.BSDFFlags.GlossyReflection), mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
        bs.sampled_type = dr.select(chose_specular, glossy, lambert)
        bs.sampled_component = dr.select(chose_specular, mi.UInt32(self._component_index("specular")),
                                         mi.UInt32(self._component_index("diffuse")))
        weight = f / dr.maximum(pdf, 1e-30)
        return bs, dr.select(active, weight, 0.0)

    def eval_diffuse_reflectance(self, si, active=True):
        return self.diffuse.eval(si, active) if self.has_diffuse else mi.Color3f(0.0)

    def to_string(self):
        lines = [f"  {DIFFUSE.name} = {self.diffuse}"]
        lines += [f"  {k} = {v}" for k, v in {**self.values, **self.textures}.items()]
        return f"{type(self).__name__}[\n  model = {self.model!r},\n" + ",\n".join(lines) + "\n]"


@functools.cache
def behaviour(cls: type[BRDFModel]) -> type:
    """The plugin behaviour of model class ``cls``: :class:`AnalyticBSDF`
    with that model and its documentation (:func:`plugin_docstring`)."""
    return type(f"{cls.__name__}BSDF", (AnalyticBSDF,), {"MODEL": cls, "__doc__": plugin_docstring(cls)})
