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

from typing import Callable, ClassVar, Iterable, Mapping, Sequence

import drjit as dr
import mitsuba as mi
import numpy as np

from .gltf_lobe import GltfLobe, nearest_lobe
from .parameter import Parameter, ParameterError, rgb

#: Cosines below this are treated as this in divisions (θ > 89.99994°).
COS_EPSILON = 1e-6
#: Most glossy lobes a model may have (Lafortune): each lobe costs a power
#: per sample, and beyond a few the fits are not determined by photographs.
MAX_LOBES = 8

#: The Lambertian term's albedo, every model's first parameter.
DIFFUSE = Parameter("diffuse_reflectance", "rgb", 0.5, 0.0, 1.0,
                    "albedo of the Lambertian term ρ_d/π")

#: Grids of lobe widths :func:`mifaces.reflectance.fit.parameters.linear_start`
#: searches: RMS slopes (Beckmann roughness, Ward's α) and cosine-lobe
#: exponents, each from a near-mirror to a near-diffuse lobe.
SLOPE_GRID = np.geomspace(0.01, 1.0, 15)
EXPONENT_GRID = np.geomspace(1.0, 1e5, 21)


def check_numbers(name: str, value, length: int | None = None, minimum: float | None = None,
                  scalar_ok: bool = False):
    """``value`` (a number, or ``length`` numbers; one number repeated where
    ``scalar_ok``) as floats, finite and at least ``minimum``; a
    ``ValueError`` naming ``name`` and the value otherwise. For the numbers
    around a BRDF: light positions, directions, intensities, angles."""
    try:
        if isinstance(value, (bool, str, dict)):
            raise TypeError
        values = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        values = None
    shape = () if length is None else (length,)
    if scalar_ok and values is not None and values.shape == ():
        values = np.full(shape, values)
    if values is None or values.shape != shape or not np.all(np.isfinite(values)) \
            or (minimum is not None and np.any(values < minimum)):
        what = "a finite number" if length is None else f"{length} finite numbers"
        bound = "" if minimum is None else f" >= {minimum:g}"
        shown = value.tolist() if isinstance(value, np.ndarray) else value
        raise ValueError(f"{name} must be {what}{bound}, got {shown!r}"[:300])
    return float(values) if length is None else values


def _numeric(value) -> bool:
    """Whether ``value`` is a number, a sequence of them or a Dr.Jit array (not a texture)."""
    return isinstance(value, (int, float, list, tuple, np.ndarray)) or dr.is_array_v(value)


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

    The model also answers what the plugin and the fitters would otherwise
    ask by its name, as pbrt's BxDFs carry their own behaviour: how it is
    read from a scene (:meth:`from_properties`), where a fit starts
    (:meth:`start_values`, :attr:`WIDTH_GRID`, :meth:`unit_lobe`,
    :meth:`scaled_lobe`), which parameters a fit holds
    (:meth:`fixed_defaults`, :meth:`fixed_in_region`), how coefficients are
    kept energy-bounded (:meth:`energy_coupled`, :meth:`coefficient_bound`),
    which lobes can be dropped (:meth:`lobe_scales`, :meth:`only_lobes`),
    how it is derived from a generic glossy lobe (:meth:`from_lobe`,
    :meth:`from_cook_torrance`) and how a ``brdf.json`` document of it is
    checked and becomes a region's plugin (:meth:`validate_document`,
    :meth:`region_plugin`, :meth:`merge_overrides`, :meth:`check_complete`)
    and how it is exported (:meth:`gltf_lobe`), as a Mitsuba built-in ground truth
    (:class:`~mifaces.brdf.builtin.BuiltinBSDF`) does.
    The defaults here fit a model with one lobe scaled by
    ``specular_reflectance``.
    """

    name: ClassVar[str]
    #: Name in prose and figure labels.
    title: ClassVar[str]
    #: option name -> allowed values; the first is the default.
    OPTIONS: ClassVar[Mapping[str, tuple[str, ...]]] = {}
    #: Whether the model takes a ``lobes`` option (several glossy lobes).
    SEVERAL_LOBES: ClassVar[bool] = False
    #: Options of the instance the plugin documentation shows.
    EXAMPLE_OPTIONS: ClassVar[Mapping] = {}
    #: (parameter, grid): the parameter that sets the lobe's width and the
    #: values :func:`~mifaces.reflectance.fit.parameters.linear_start` tries; None:
    #: the model has no such parameter and a fit starts from :meth:`start_values`.
    WIDTH_GRID: ClassVar[tuple[str, np.ndarray] | None] = None
    #: The end of the width parameter's range where the lobe becomes a spike
    #: (``'lower'`` for a slope, ``'upper'`` for an exponent): a fit that ends
    #: there resolves a highlight no photograph can, and is not trusted.
    SHARP_END: ClassVar[str] = "lower"

    def __init__(self, **options):
        unknown = set(options) - set(self.OPTIONS)
        if unknown:
            raise ValueError(f"{self.name}: unknown option(s) {sorted(unknown)}; "
                             f"known: {sorted(self.OPTIONS)}")
        self.options = {}
        for key, default in self.default_options().items():
            choices = self.OPTIONS[key]
            value = options.get(key, default)
            if value not in choices:
                raise ValueError(f"{self.name}: option {key}={value!r} is not one of {choices}")
            self.options[key] = value
            setattr(self, key, value)

    @classmethod
    def default_options(cls) -> dict:
        """Option name -> its default, the first of its :attr:`OPTIONS`."""
        return {key: choices[0] for key, choices in cls.OPTIONS.items()}

    @classmethod
    def from_properties(cls, keys: Iterable[str], get: Callable) -> BRDFModel:
        """The model described by a scene's properties: ``keys`` are the
        names given, ``get(name, default)`` reads one (Mitsuba's
        ``Properties.keys`` and ``Properties.get``); an option the scene
        does not give takes its :meth:`default_options` value."""
        return cls(**{key: get(key, default) for key, default in cls.default_options().items()})

    # -- description ----------------------------------------------------
    def specular_parameters(self) -> tuple[Parameter, ...]:
        """Parameters of the glossy part."""
        raise NotImplementedError

    def parameters(self) -> tuple[Parameter, ...]:
        """All parameters: ``diffuse_reflectance`` then the glossy ones."""
        return (DIFFUSE,) + self.specular_parameters()

    def parameter(self, name: str) -> Parameter:
        """The parameter called ``name``."""
        return next(p for p in self.parameters() if p.name == name)

    def validate(self, params: Mapping, where: str = "") -> dict:
        """The parameters ``params`` (name -> value) checked by
        :meth:`Parameter.check`, as plain floats (RGB as three).

        This is the one validation of BRDF parameters: the plugins'
        constructors and ``parameters_changed``, the face scenes, the
        simulator's ground truth and :func:`mifaces.reflectance.io.load_estimate`
        call it. A texture (a non-numeric ``diffuse_reflectance``) is passed
        through unchecked.

        Raises
        ------
        ParameterError
            Naming ``where`` (e.g. the region), the parameter and its value:
            a name the model does not have, a value that is not finite, not a
            number (or three) or outside the parameter's range.
        """
        known = {p.name: p for p in self.parameters()}
        out = {}
        for name, value in params.items():
            if name not in known:
                prefix = f"{where}: " if where else ""
                raise ParameterError(f"{prefix}{self.name} has no parameter {name!r}; its parameters: "
                                     f"{sorted(known)}")
            if name == DIFFUSE.name and not _numeric(value):
                out[name] = value
                continue
            out[name] = known[name].check(value, where)
        return out

    def validate_regions(self, regions, fallback: str = "skin") -> dict:
        """Per-region glossy parameters (the ``regions`` of ``brdf.json``),
        each region's checked by :meth:`validate` (a parameter not given
        takes its default); ``fallback``, the region the others default to,
        must be present."""
        if not isinstance(regions, dict) or not regions:
            raise ParameterError(f"regions must map region names to parameter objects, got {regions!r}"[:300])
        if fallback not in regions:
            raise ParameterError(f"regions: no {fallback!r} region (the one every region without its own "
                                 f"parameters takes); regions given: {sorted(regions)}")
        out = {}
        for region, params in regions.items():
            if not isinstance(params, dict):
                raise ParameterError(f"region {region!r}: parameters must be an object, got {params!r}"[:300])
            out[region] = self.validate(params, f"region {region!r}")
        return out

    def defaults(self) -> dict:
        """Default value of every parameter (floats)."""
        return {p.name: p.default for p in self.parameters()}

    # -- documents (``brdf.json``) and plugins ---------------------------------
    def validate_document(self, document: Mapping) -> dict:
        """A BRDF of this model in the ``brdf.json`` layout
        (``{"model", "options", "regions"}``), its regions checked by
        :meth:`validate_regions`; see :func:`mifaces.brdf.validate_brdf`."""
        options = document.get("options", {})
        return dict(document, options=dict(options), regions=self.validate_regions(document.get("regions")))

    def plugin_options(self, options: Mapping) -> dict:
        """The properties of this model's plugin for a document's
        ``options``: all but ``lobes``, which every model accepts as 1
        (:func:`mifaces.brdf.model`) and a plugin reads from the lobe
        parameters a scene names (:meth:`from_properties`)."""
        return {k: v for k, v in options.items() if k != "lobes"}

    def region_plugin(self, params: Mapping, texture, options: Mapping | None = None) -> dict:
        """The Mitsuba dict of a region's ``params`` over diffuse ``texture`` (None: the plugin's
        default), with the model's ``options`` (a ``brdf.json``'s)."""
        d = {"type": self.name} if texture is None else {"type": self.name, DIFFUSE.name: texture}
        d.update(self.plugin_options(options or {}))
        kinds = {p.name: p.kind for p in self.specular_parameters()}
        for k, v in params.items():
            d[k] = rgb(v) if kinds.get(k) == "rgb" else float(v)
        return d

    def merge_overrides(self, base: Mapping, params: Mapping) -> dict:
        """A region's parameters ``base`` with ``params`` replacing them."""
        return dict(base, **params)

    def check_complete(self, params: Mapping, where: str) -> None:
        """A ``ValueError`` naming ``where`` unless ``params`` gives every glossy parameter."""
        missing = [p.name for p in self.specular_parameters() if p.name not in params]
        if missing:
            raise ValueError(f"{where}: {self.name} with {len(self.lobe_scales())} lobes needs {', '.join(missing)}")

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options.items())
        return f"{type(self).__name__}({opts})"

    # -- fitting -----------------------------------------------------------
    def start_values(self) -> dict:
        """Start of a fit's glossy parameters when nothing better is known:
        each parameter's :attr:`Parameter.start` (floats, RGB as three)."""
        return {p.name: p.start_value() for p in self.specular_parameters()}

    def fixed_defaults(self) -> dict:
        """Parameters a fit holds fixed unless the caller frees them (none)."""
        return {}

    def fixed_in_region(self, region: str) -> dict:
        """Parameters a fit holds fixed in face region ``region`` at a
        published value, on top of :meth:`fixed_defaults` (none)."""
        return {}

    def unit_lobe(self) -> dict:
        """Glossy parameters that make the lobe's scale 1, given every
        parameter's default and the width on :attr:`WIDTH_GRID`: the lobe g
        of r ≈ ρ_d + b·g in :func:`~mifaces.reflectance.fit.parameters.linear_start`."""
        return {"specular_reflectance": 1.0}

    def scaled_lobe(self, scales: Sequence[float], width: float) -> dict:
        """Glossy parameters of the unit lobe at ``width`` scaled by ``scales``
        (b per colour channel, >= 0), kept inside the valid range."""
        spec = self.parameter("specular_reflectance")
        return {spec.name: [float(np.clip(b, spec.upper * 1e-4, spec.upper * 0.999)) for b in scales]}

    def energy_coupled(self) -> dict[str, str]:
        """Coefficient name -> name of the exponent whose
        :meth:`coefficient_bound` limits it (none)."""
        return {}

    def coefficient_bound(self, exponent, log, exp):
        """Largest magnitude of a coefficient of :meth:`energy_coupled` for
        ``exponent``, written with the given ``log`` and ``exp`` (numpy's or
        Dr.Jit's)."""
        raise NotImplementedError(f"{self.name} has no energy-coupled coefficients")

    def lobe_scales(self) -> dict[int, tuple[str, ...]]:
        """Lobe number -> the parameters that scale it: a lobe whose scales
        are all zero reflects nothing and can be left out."""
        return {1: ("specular_reflectance",)}

    def only_lobes(self, lobes: Sequence[int]) -> BRDFModel:
        """This model with only the lobes numbered ``lobes`` evaluated."""
        return self

    def from_lobe(self, albedo: Sequence[float], roughness: float) -> dict:
        """Glossy parameters of this model for a generic glossy lobe: one of
        directional albedo ``albedo`` (RGB) at normal incidence and as wide
        as a Beckmann lobe of RMS slope ``roughness``."""
        raise NotImplementedError(f"{self.name} is not derived from a generic lobe")

    def from_cook_torrance(self, region: Mapping) -> dict:
        """Glossy parameters of this model for one region of the published
        Cook–Torrance skin values (``specular_reflectance``, ``roughness``,
        ``eta``; :data:`mifaces.studio.truth.COOK_TORRANCE_REGIONS`): the
        simulator's ground truth. The other models derive theirs by
        :func:`mifaces.brdf.cooktorrance.from_cook_torrance_lobe`."""
        raise NotImplementedError(f"{self.name} is not derived from Cook–Torrance values")

    # -- export (glTF 2.0: mifaces.brdf.gltf_lobe) --------------------------
    def region_values(self, params: Mapping, region: str) -> dict:
        """Face region ``region``'s glossy ``params`` completed by what a fit holds there
        (:meth:`fixed_defaults`, :meth:`fixed_in_region`, e.g. Cook–Torrance's η): all that
        the region's lobe depends on, so regions of equal values have one lobe."""
        return {**self.fixed_defaults(), **self.fixed_in_region(region), **params}

    def gltf_lobe(self, params: Mapping) -> GltfLobe:
        """The glTF specular layer of the glossy part with ``params`` (:meth:`region_values`):
        the nearest GGX lobe by least squares (:func:`~mifaces.brdf.gltf_lobe.nearest_lobe`),
        unless the model maps its parameters in closed form."""
        return nearest_lobe(self, params)

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
