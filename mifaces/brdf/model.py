"""What every analytic BRDF model of mifaces shares: parameters, the diffuse
term, the horizon, and the interface the plugins and the fitters call.

Conventions, held by every model
--------------------------------
* Directions ``wi`` (towards the light) and ``wo`` (towards the viewer) are
  unit vectors in the **local shading frame** (z = surface normal), both
  pointing away from the surface. The models are reciprocal, so the two may
  be swapped.
* ``eval`` returns the BRDF value f(wi, wo) in 1/sr **without** the cosine
  foreshortening term. The Mitsuba plugins multiply by cos θo themselves.
* f = 0 unless both directions are strictly above the horizon (z > 0).
* The diffuse term is Lambertian: ρ_d / π, so ``diffuse_reflectance`` is the
  albedo of that term.
* Parameters are passed as a mapping from the plugin's parameter name to a
  Dr.Jit value: ``mi.Color3f`` (or a float, broadcast) for RGB parameters,
  ``mi.Float`` (or a float) for scalar ones. Arrays of per-sample values are
  fine: everything is elementwise.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Mapping

import drjit as dr
import mitsuba as mi

#: Cosines below this are treated as this in divisions (θ > 89.99994°).
COS_EPSILON = 1e-6


@dataclass(frozen=True)
class Parameter:
    """One parameter of a BRDF model.

    Attributes
    ----------
    name : str
        The name used by the plugin (XML, ``mi.traverse``) and in ``brdf.json``.
    kind : str
        ``'rgb'`` (three channels) or ``'float'``.
    default : float
        Value used when a scene does not give one.
    lower, upper : float
        The physically valid range, for fitting and validation.
    doc : str
        One line for the docs.
    """

    name: str
    kind: str
    default: float
    lower: float
    upper: float
    doc: str


DIFFUSE = Parameter("diffuse_reflectance", "rgb", 0.5, 0.0, 1.0,
                    "albedo of the Lambertian term ρ_d/π")


def dot(a, b):
    """a·b of two 3-vectors, written out.

    Dr.Jit 1.5's ``dr.dot`` makes these models' LLVM kernels 2-4x slower
    once the result feeds several colour channels (measured: 58 ms against
    16 ms for ``dot(wi, wo) + rgb`` on 10^7 samples); the spelled-out sum
    compiles to the same three multiply-adds without that cost."""
    return a.x * b.x + a.y * b.y + a.z * b.z


def safe_divide(a, b, eps=1e-20):
    """a / b with |b| kept above ``eps`` (sign preserved), so that neither the
    value nor its gradient becomes infinite."""
    b = dr.select(b >= 0, dr.maximum(b, eps), dr.minimum(b, -eps))
    return a / b


#: Natural log of the smallest normal float32 (2^-126).
_LOG_MIN_NORMAL = -87.33


def exp_flushed(x):
    """exp(x), flushed to 0 where it would be a denormal float32 (x < -87.3).

    Denormals are meaningless for reflectance and make x86 arithmetic up to
    ten times slower; sharp lobes produce them on most of the hemisphere."""
    return dr.select(x > _LOG_MIN_NORMAL, dr.exp(dr.maximum(x, _LOG_MIN_NORMAL)), 0.0)


def power(base, exponent):
    """``max(base, 0) ** exponent`` = 2^(n log2 base), whose value and
    gradient stay finite for base -> 0 and exponents from 1 to 1e5 (the
    unused branch is fed 1), flushed to 0 below float32's normal range."""
    safe = dr.select(base > 0, base, 1.0)
    x = exponent * dr.log2(safe)
    return dr.select((base > 0) & (x > -126.0), dr.exp2(dr.maximum(x, -126.0)), 0.0)


def mean(value):
    """Mean over colour channels of an RGB value (or the value itself)."""
    return dr.mean(value) if dr.size_v(value) == 3 else value


class BRDFModel:
    """Base of the analytic models: diffuse term + one glossy part.

    A model object carries only the model's fixed *options* (e.g. which
    Fresnel term); the parameter values are passed to every call, so one
    object serves a plugin and a fitter alike. Subclasses implement
    :meth:`specular`, :meth:`sample_specular`, :meth:`pdf_specular` and
    :meth:`specular_weight`.
    """

    name: ClassVar[str]
    #: option name -> allowed values; the first is the default.
    OPTIONS: ClassVar[Mapping[str, tuple[str, ...]]] = {}

    def __init__(self, **options):
        unknown = set(options) - set(self.OPTIONS)
        if unknown:
            raise ValueError(f"{self.name}: unknown option(s) {sorted(unknown)}; "
                             f"known: {sorted(self.OPTIONS)}")
        self.options = {}
        for key, choices in self.OPTIONS.items():
            value = options.get(key, choices[0])
            if value not in choices:
                raise ValueError(f"{self.name}: option {key}={value!r} is not one of {choices}")
            self.options[key] = value
            setattr(self, key, value)

    # -- description ----------------------------------------------------
    def specular_parameters(self) -> tuple[Parameter, ...]:
        """Parameters of the glossy part."""
        raise NotImplementedError

    def parameters(self) -> tuple[Parameter, ...]:
        """All parameters: ``diffuse_reflectance`` then the glossy ones."""
        return (DIFFUSE,) + self.specular_parameters()

    def defaults(self) -> dict:
        """Default value of every parameter (floats)."""
        return {p.name: p.default for p in self.parameters()}

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options.items())
        return f"{type(self).__name__}({opts})"

    # -- the formulas ----------------------------------------------------
    def specular(self, wi, wo, params):
        """Glossy part f_s(wi, wo) (RGB, 1/sr, no cosine), for directions
        above the horizon; :meth:`eval` applies the horizon."""
        raise NotImplementedError

    def eval(self, wi, wo, params, diffuse: bool = True, specular: bool = True):
        """f(wi, wo) = ρ_d/π + f_s(wi, wo), RGB, without the cosine term.

        Parameters
        ----------
        wi, wo : mi.Vector3f
            Unit directions in the local frame, pointing away from the surface.
        params : mapping
            Parameter name -> value (see module docstring).
        diffuse, specular : bool
            Include that part. A plugin leaves out a part whose weight is zero.
        """
        above = (wi.z > 0) & (wo.z > 0)
        value = mi.Color3f(0.0)
        if diffuse:
            value += mi.Color3f(params[DIFFUSE.name]) * dr.inv_pi
        if specular:
            value += self.specular(wi, wo, params)
        return dr.select(above, value, 0.0)

    # -- sampling ----------------------------------------------------------
    def specular_weight(self, wi, params):
        """A non-negative estimate of the glossy part's albedo at ``wi``,
        comparable with the diffuse albedo; it sets how often the plugin
        samples the glossy part rather than the diffuse one."""
        raise NotImplementedError

    def sample_specular(self, wi, sample1, sample2, params):
        """Importance-sample an outgoing direction from the glossy part.

        ``sample1`` (uniform in [0, 1)) picks a lobe where there are several,
        ``sample2`` (mi.Point2f) the direction. The direction may point below
        the horizon; the caller rejects it then.
        """
        raise NotImplementedError

    def pdf_specular(self, wi, wo, params):
        """Solid-angle density of :meth:`sample_specular` at ``wo``."""
        raise NotImplementedError
