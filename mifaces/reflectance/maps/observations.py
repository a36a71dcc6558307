"""Pixels under many lights on the Dr.Jit side, for the per-pixel normal step
of :mod:`mifaces.reflectance.maps.normal_fit`: the shading of each observation by
an analytic BRDF and its derivatives with respect to the normal."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ...brdf.model import BRDFModel
from ..footprint import spread_arrays, tilts


def tangents(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An orthonormal tangent pair per unit normal (Duff et al. 2017), (P, 3) each."""
    x, y, z = normals.T
    sign = np.where(z >= 0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    t1 = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    t2 = np.stack([b, sign + y * y * a, -y], axis=1)
    return t1, t2


def vectors(a: np.ndarray) -> mi.Vector3f:
    return mi.Vector3f(np.ascontiguousarray(np.asarray(a, np.float32).T))


def glossy_params(model: BRDFModel, params: dict) -> dict:
    """θ as opaque Dr.Jit values: one kernel serves every value of the fit."""
    out = {}
    for p in model.specular_parameters():
        value = np.broadcast_to(np.asarray(params[p.name], np.float64), (3,) if p.kind == "rgb" else ())
        if p.kind == "rgb":
            out[p.name] = mi.Color3f(*[dr.opaque(mi.Float, float(v)) for v in value])
        else:
            out[p.name] = dr.opaque(mi.Float, float(value))
    return out


class Observations:
    """P pixels under K lights on the Dr.Jit side, pixel-major (observation i = p·K + k).

    Evaluates s = max(0, n·l) and g = π f_s(l̂, v̂) s for the glossy parameters
    θ, and reduces per pixel with block sums, so only per-pixel arrays cross
    to numpy. ``values`` (K, P, 3) and ``weights`` (K, P) may be None for
    :meth:`shading` alone. ``view`` is (3,), (P, 3) or, one per observation, (K, P, 3).
    ``footprint`` (K, P, 3), optional: each observation's pixel footprint, the covariance (tt, tb,
    bb) of the normal's tilt along the frame's x and y axes
    (:mod:`mifaces.reflectance.footprint`): the glossy shading g is then the mean of
    :func:`~mifaces.reflectance.footprint.tilts`' normals' π f_s cos θl, weighted.
    """

    def __init__(self, model: BRDFModel, params: dict, directions, view, pixels: int, values=None, weights=None,
                 footprint=None):
        k = len(directions)
        directions = np.broadcast_to(np.asarray(directions, np.float64).reshape(k, -1, 3), (k, pixels, 3))
        self.model, self.params, self.k, self.p = model, glossy_params(model, params), k, pixels
        self.light = vectors(np.transpose(directions, (1, 0, 2)).reshape(-1, 3))
        view = np.asarray(view, np.float64)
        if view.ndim == 3:  # one view direction per observation (texels seen in several poses)
            self.view = vectors(np.transpose(np.broadcast_to(view, (k, pixels, 3)), (1, 0, 2)).reshape(-1, 3))
        else:
            self.view = vectors(np.repeat(np.broadcast_to(view.reshape(-1, 3), (pixels, 3)), k, axis=0))
        self.pixel = dr.arange(mi.UInt32, pixels * k) // k
        self.tilts = ()
        if footprint is not None:
            spread = np.transpose(np.asarray(footprint, np.float32), (1, 0, 2)).reshape(pixels * k, 3)
            self.tilts = tuple((mi.Vector3f(x, y, 0.0), w) for x, y, w in tilts(spread_arrays(spread, pixels * k)))
            dr.eval([t for t, _ in self.tilts])
        if values is not None:
            self.value = mi.Color3f(np.ascontiguousarray(
                np.transpose(np.asarray(values, np.float32), (1, 0, 2)).reshape(-1, 3).T))
            self.weight = mi.Float(np.ascontiguousarray(np.asarray(weights, np.float32).T).ravel())

    def _expand(self, a: np.ndarray) -> mi.Vector3f:
        return dr.gather(mi.Vector3f, vectors(a), self.pixel)

    def _terms(self, n, t1=None, t2=None, a=None, b=None):
        n = n if a is None else dr.normalize(n + a * t1 + b * t2)
        s, g = self._shade(n)
        if self.tilts:  # the footprint: the glossy part averaged over the tilted normals
            g = dr.zeros(mi.Color3f, dr.width(s))
            for tilt, weight in self.tilts:
                g += self._shade(dr.normalize(n + tilt))[1] * weight
        return s, g

    def _shade(self, n):
        """s = max(0, n·l) and g = π f_s s at normals ``n``."""
        frame = mi.Frame3f(n)
        wi, wo = frame.to_local(self.light), frame.to_local(self.view)
        s = dr.select((wi.z > 0) & (wo.z > 0), wi.z, 0.0)
        return s, dr.pi * self.model.eval(wi, wo, self.params, diffuse=False) * s

    def shading(self, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """s (K, P) and g (K, P, 3) at unit ``normals`` (P, 3)."""
        s, g = self._terms(self._expand(normals))
        return (np.array(s, np.float64).reshape(self.p, self.k).T,
                np.transpose(np.array(g, np.float64).T.reshape(self.p, self.k, 3), (1, 0, 2)))

    def _albedo(self, s, g) -> mi.Color3f:
        ws = self.weight * s
        num = dr.block_sum(ws * (self.value - g), self.k)
        den = dr.block_sum(ws * s, self.k)
        return dr.select(den > 0, num / dr.maximum(den, 1e-30), 0.0)

    def losses(self, normals: np.ndarray, albedo: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Each pixel's data term Σ_k w |I - ρ s - g|² (P,) and its ρ (P, 3): ``albedo``, or
        where None the closed form ρ_c = Σ_k w s (I_c - g_c) / Σ_k w s² (0 where no usable
        observation is lit), as :mod:`mifaces.reflectance.maps.diffuse` does per texel."""
        s, g = self._terms(self._expand(normals))
        dr.eval(s, g)  # shaded once: each block sum below would otherwise run the shading again
        rho = self._albedo(s, g) if albedo is None else mi.Color3f(vectors(albedo))
        r = self.value - dr.gather(mi.Color3f, rho, self.pixel) * s - g
        loss = dr.block_sum(self.weight * (dr.square(r.x) + dr.square(r.y) + dr.square(r.z)), self.k)
        dr.eval(loss, rho)
        return np.array(loss, np.float64), np.array(rho, np.float64).T

    def system(self, normals, albedo, t1, t2):
        """The data term's Gauss-Newton matrix H (P, 5, 5), gradient (P, 5) and value (P,) in
        (a, b, ρ_rgb), the tangent coordinates of n = normalise(n₀ + a t₁ + b t₂) at a = b = 0
        and the albedo; the derivatives in a and b by forward-mode AD, one pass each."""
        n = self.k * self.p
        a, b = dr.zeros(mi.Float, n), dr.zeros(mi.Float, n)
        dr.enable_grad(a, b)
        s, g = self._terms(self._expand(normals), self._expand(t1), self._expand(t2), a, b)
        rho = dr.gather(mi.Color3f, mi.Color3f(vectors(albedo)), self.pixel)
        tangent = []
        for u in (a, b):
            dr.forward_from(u, flags=dr.ADFlag.ClearVertices)
            tangent.append(rho * dr.grad(s) + dr.grad(g))  # dÎ/du, Î = ρ s + g
            dr.eval(tangent[-1], *(() if tangent[1:] else (s, g)))  # s and g in the first pass's kernel
            dr.clear_grad(s)
            dr.clear_grad(g)
        s, g = dr.detach(s), dr.detach(g)
        r = self.value - rho * s - g
        w, ws = self.weight, self.weight * s
        total = lambda x: dr.block_sum(x, self.k)  # noqa: E731
        dot = lambda x, y: x.x * y.x + x.y * y.y + x.z * y.z  # noqa: E731
        da, db = tangent
        sums = [total(w * dot(da, da)), total(w * dot(da, db)), total(w * dot(db, db)), total(ws * da),
                total(ws * db), total(ws * s), total(w * dot(da, r)), total(w * dot(db, r)), total(ws * r),
                total(w * dot(r, r))]
        dr.eval(*sums)
        aa, ab, bb, ar, br, rr, ga, gb, gr, value = [np.array(x, np.float64) for x in sums]
        h = np.zeros((self.p, 5, 5))
        h[:, 0, 0], h[:, 0, 1], h[:, 1, 0], h[:, 1, 1] = aa, ab, ab, bb
        h[:, 0, 2:] = h[:, 2:, 0] = ar.T
        h[:, 1, 2:] = h[:, 2:, 1] = br.T
        h[:, 2:, 2:] = rr[:, None, None] * np.eye(3)
        grad = -np.concatenate([ga[:, None], gb[:, None], gr.T], axis=1)  # J = -dÎ
        return h, grad, value
