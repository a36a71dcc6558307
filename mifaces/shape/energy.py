"""The energy of a shape fit, ``E = E_I + E_F + E_P`` (paper sec. 4.2), on the
Dr.Jit side and differentiable (reverse mode).

* ``E_I``: squared RGB differences between the photograph and a Phong
  rendering of the model in the model's domain -- sample vertices projected
  into the image, the image sampled bilinearly there, compared with ambient +
  directed light (cast shadow) + a specular lobe, then colour contrast, gain
  and offset (Blanz and Vetter 1999, sec. 4); one term per photograph.
* ``E_F``: squared image distances between the model's feature points and the
  clicked ones.
* ``E_P``: the Mahalanobis norm of the coefficients (Blanz and Vetter 1999,
  eq. 3), log focal length around the calibration, the capture's metric
  distances on the identity shape, and for a model without colour model the
  per-vertex albedo's deviation from its mean.

Parameters enter as one opaque array and the fading weights are opaque too,
so kernels are cached across iterations.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .result import Weights
from .targets import FRONTAL, blurred

#: Phong exponent of the specular lobe (fixed; its strength is fitted).
PHONG_EXPONENT = 16.0
#: Rec. 601 luminance weights of the colour-contrast operator (Blanz and Vetter 1999).
LUMINANCE = (0.3, 0.59, 0.11)


class Layout:
    """Named blocks of the parameter vector and their natural units (Adam works on theta / unit)."""

    IMAGE_BLOCK = (("light_angles", 2, 0.15), ("light_color", 3, 0.15), ("ambient", 3, 0.1),
                   ("specular", 1, 0.05), ("contrast", 1, 0.1), ("gain", 3, 0.1), ("offset", 3, 0.03))

    def __init__(self, model, images: list[str]):
        self.slices, units = {}, []

        def add(name, n, unit):
            self.slices[name] = slice(len(units), len(units) + n)
            units.extend([unit] * n)

        add("rotation", 3, 0.05)
        add("translation", 3, 5.0)
        add("log_focal", 1, 0.02)
        for image in images:
            for name, n, unit in self.IMAGE_BLOCK:
                add(f"{image}.{name}", n, unit)
        add("shape", model.shape_dim, 1.0)
        add("expression", model.expression_dim, 1.0)
        if model.has_texture:
            add("color", model.color_dim, 0.3)
        else:
            add("albedo", 3 * model.vertex_count, 0.03)
        self.units = np.array(units, np.float64)
        self.size = len(units)

    def __getitem__(self, name):
        return self.slices[name]


def adjacency(triangles: np.ndarray, vertex_count: int) -> np.ndarray:
    """(N, D) triangle indices adjacent to each vertex, padded with -1."""
    t = np.asarray(triangles, np.int64)
    corner_vertex = t.ravel()
    corner_triangle = np.repeat(np.arange(len(t)), 3)
    order = np.argsort(corner_vertex, kind="stable")
    cv, ct = corner_vertex[order], corner_triangle[order]
    counts = np.bincount(cv, minlength=vertex_count)
    d = max(int(counts.max()), 1)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(len(cv)) - starts[cv]
    out = np.full((vertex_count, d), -1, np.int64)
    out[cv, slot] = ct
    return out


class Energy:
    """E of one fit for the sampled vertices, on the Dr.Jit side.

    Parameters
    ----------
    model : MorphableModel
    camera : mifaces.capture.Camera
    layout : Layout
    weights : Weights
    images : dict
        Image name (``'point'``, ``'diffuse'``) -> normalised (H, W, 3) float32 photograph.
    feature_vertices, feature_pixels : (F,) int, (F, 2) float
        The feature points' model vertices and their clicked pixels.
    distances : list of (int, int, float)
        Metric distances ``(vertex, vertex, mm)`` on the identity shape.
    centre : (3,) float
        The rotation centre (model space, mm).
    light_distance : float
        Distance (mm) of the point image's lamp from the face centre; inf for a directional light.
    """

    def __init__(self, model, camera, layout: Layout, weights: Weights, images: dict, feature_vertices,
                 feature_pixels, distances, centre, light_distance: float = math.inf):
        self.model, self.camera, self.layout, self.weights = model, camera, layout, weights
        self.images = images
        self.image_names = list(images)
        self.feature_vertices, self.feature_pixels = feature_vertices, feature_pixels
        self.distances = distances
        self.distance_vertices = np.array([[a, b] for a, b, _ in distances], np.int64).reshape(-1, 2)
        self.centre = centre
        self.light_distance = light_distance
        self.scale_px = camera.height / 512.0  # px per "512-px pixel"
        self.adjacency = adjacency(model.triangles, model.vertex_count)

    # ---- the sample set and the image level ---------------------------------------------------
    def set_samples(self, samples: np.ndarray):
        """Move the model rows the sample vertices ``samples``, their one-rings, the feature points
        and the metric distances need to the Dr.Jit side; every sample visible and lit."""
        m = self.model
        adj = self.adjacency[samples]  # (S, D)
        valid = adj >= 0
        ring_tris = m.triangles[np.where(valid, adj, 0)]  # (S, D, 3)
        needed = np.unique(np.concatenate([samples, ring_tris[valid].ravel(), self.feature_vertices,
                                           self.distance_vertices.ravel()]))
        local = np.full(m.vertex_count, -1, np.int64)
        local[needed] = np.arange(len(needed))
        self.n_samples, self.degree = len(samples), adj.shape[1]
        rows = (3 * needed[:, None] + np.arange(3)).ravel()
        sigma = np.sqrt(m.shape_variance).astype(np.float64)
        columns = [m.shape_basis[rows] * sigma]
        if m.has_expressions:
            columns.append(m.expression_basis[rows] * np.sqrt(m.expression_variance))
        basis = np.concatenate(columns, axis=1).astype(np.float32)
        self.n_modes = basis.shape[1]
        self.dr_mean = mi.Float(m.shape_mean[needed].astype(np.float32).ravel())
        self.dr_basis = [mi.Float(np.ascontiguousarray(basis[:, k])) for k in range(self.n_modes)]
        self.dr_sample_local = mi.UInt32(local[samples].astype(np.uint32))
        self.dr_feature_local = mi.UInt32(local[self.feature_vertices].astype(np.uint32))
        if len(self.distances):
            self.dr_distance_local = [mi.UInt32(local[self.distance_vertices[:, k]].astype(np.uint32))
                                      for k in range(2)]
            self.dr_distance_mm = mi.Float(np.array([d for _, _, d in self.distances], np.float32))
        corners = local[ring_tris]  # (S, D, 3)
        corners = np.where(valid[..., None], corners, 0).astype(np.uint32)
        self.dr_corners = [mi.UInt32(np.ascontiguousarray(corners[..., c].ravel())) for c in range(3)]
        self.dr_slot_valid = mi.Float(valid.astype(np.float32).ravel())
        if m.has_texture:
            crow = (3 * samples[:, None] + np.arange(3)).ravel()
            cbasis = m.color_basis[crow] * np.sqrt(m.color_variance)
            self.dr_color_mean = mi.Float(m.color_mean[samples].astype(np.float32).ravel())
            self.dr_color_basis = [mi.Float(np.ascontiguousarray(cbasis[:, k].astype(np.float32)))
                                   for k in range(m.color_dim)]
        self.dr_sample_vertex = mi.UInt32(samples.astype(np.uint32))
        ones = np.ones(len(samples), np.float32)
        self.set_visibility(ones, ones)

    def set_visibility(self, seen: np.ndarray, lit: np.ndarray):
        """Per sample: seen by the camera (every image), lit by the point image's lamp (0 or 1)."""
        self.dr_visible = {k: mi.Float(np.asarray(seen, np.float32)) for k in self.image_names}
        self.dr_shadow = mi.Float(np.asarray(lit, np.float32))

    def set_level(self, blur: float):
        """The photographs blurred by ``blur`` px at 512 px image height, on the Dr.Jit side."""
        self.dr_images = {}
        for key, image in self.images.items():
            b = blurred(image, blur * self.scale_px)
            self.dr_images[key] = mi.Float(np.ascontiguousarray(b, np.float32).ravel())

    # ---- synthesis -----------------------------------------------------------------------------
    def _scalar(self, theta, i: int):
        return dr.gather(mi.Float, theta, mi.UInt32(i))

    def _block(self, theta, name: str):
        s = self.layout[name]
        return [self._scalar(theta, i) for i in range(s.start, s.stop)]

    def _rotation(self, theta):
        """Rows of ``R0 R_y R_x R_z`` as Dr.Jit scalars (row-major 3x3 list)."""
        yaw, pitch, roll = self._block(theta, "rotation")
        cy, sy, cp, sp, cr, sr = dr.cos(yaw), dr.sin(yaw), dr.cos(pitch), dr.sin(pitch), dr.cos(roll), dr.sin(roll)
        # R_y R_x R_z, expanded
        r = [[cy * cr + sy * sp * sr, -cy * sr + sy * sp * cr, sy * cp],
             [cp * sr, cp * cr, -sp],
             [-sy * cr + cy * sp * sr, sy * sr + cy * sp * cr, cy * cp]]
        return [[float(FRONTAL[i, i]) * r[i][j] for j in range(3)] for i in range(3)]

    def positions(self, theta):
        """Model-space positions of the needed vertices (flat Floats ``x0, y0, z0, ...``):
        ``(with expression, identity only)``. The expression block follows the shape block
        in the parameter vector, and its columns follow the shape columns in the basis."""
        p = self.dr_mean
        s = self.layout["shape"].start
        identity = p
        for k in range(self.n_modes):
            p = p + self.dr_basis[k] * self._scalar(theta, s + k)
            if k == self.model.shape_dim - 1:
                identity = p
        return p, identity

    def _to_camera(self, p, R, t):
        """Camera-space coordinates ``R (p - c) + t`` of model-space points ``p`` (3 Floats)."""
        c = [float(x) for x in self.centre]
        q = [p[0] - c[0], p[1] - c[1], p[2] - c[2]]
        return [R[i][0] * q[0] + R[i][1] * q[1] + R[i][2] * q[2] + t[i] for i in range(3)]

    def _project(self, pc, focal):
        """Pixel coordinates of camera-space points (OpenCV model with distortion)."""
        cam = self.camera
        z = dr.maximum(pc[2], 1.0)
        x, y = pc[0] / z, pc[1] / z
        if np.any(cam.distortion):
            d = np.zeros(8)
            d[:len(cam.distortion)] = cam.distortion
            k1, k2, p1, p2, k3, k4, k5, k6 = (float(v) for v in d)
            r2 = x * x + y * y
            radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
            x, y = (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                    y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)
        return focal * cam.fx * x + cam.cx, focal * cam.fy * y + cam.cy

    def _bilinear(self, image, u, v):
        """Image (flat RGB Float) at pixel coordinates (u, v), bilinear; returns (rgb, inside)."""
        w, h = self.camera.width, self.camera.height
        inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
        uc, vc = dr.clip(u, 0, w - 1.001), dr.clip(v, 0, h - 1.001)
        x0, y0 = dr.floor(uc), dr.floor(vc)
        fx, fy = uc - x0, vc - y0
        i0 = mi.UInt32(y0) * w + mi.UInt32(x0)

        def at(i):
            return dr.gather(mi.Vector3f, image, i)

        top = at(i0) * (1 - fx) + at(i0 + 1) * fx
        bottom = at(i0 + w) * (1 - fx) + at(i0 + w + 1) * fx
        return top * (1 - fy) + bottom * fy, inside

    # ---- the terms -----------------------------------------------------------------------------
    def evaluate(self, theta_np: np.ndarray, feature_weight: float, image_weight: float, grad: bool = True):
        """E and its terms for parameters ``theta_np``; with ``grad``, also dE/dtheta (numpy).

        ``feature_weight`` multiplies :attr:`Weights.feature`; ``image_weight`` E_I (0: E_I is not
        evaluated). Returns the terms ``E, E_I, E_F, E_P, E_D`` (E_D, the metric distances, is
        part of E_P), ``feature_rms_px`` and, with the image term, ``image_rms``; and the gradient.
        """
        L, w = self.layout, self.weights
        theta = mi.Float(theta_np.astype(np.float32))
        if grad:
            dr.enable_grad(theta)
        R = self._rotation(theta)
        t = self._block(theta, "translation")
        focal = dr.exp(self._scalar(theta, L["log_focal"].start))
        pos, neutral = self.positions(theta)
        e_f, f_sq = self._feature_term(pos, R, t, focal)
        e_p = self._coefficient_prior(theta)
        e_d = mi.Float(0.0)
        if len(self.distances):
            e_d = self._distance_term(neutral)
            e_p = e_p + e_d
        e_i, stats = mi.Float(0.0), {}
        if image_weight > 0:
            e_i, albedo_prior, stats = self._image_term(theta, pos, R, t, focal)
            if albedo_prior is not None:
                e_p = e_p + albedo_prior
        # the weights change every iteration while E_F fades: opaque, so kernels stay cached
        energy = (dr.opaque(mi.Float, image_weight) * e_i +
                  dr.opaque(mi.Float, feature_weight * w.feature) * e_f + e_p)
        if grad:
            dr.backward(energy)
            g = np.asarray(dr.grad(theta), np.float64)
        else:
            g = None
        frms = math.sqrt(float(dr.sum(f_sq)[0]) / len(self.feature_vertices)) * self.scale_px
        terms = {"E": float(energy[0]), "E_I": float(e_i[0]), "E_F": float(e_f[0]), "E_P": float(e_p[0]),
                 "E_D": float(e_d[0]), "feature_rms_px": frms}
        if stats:
            num = sum(float(dr.sum(r * wt)[0]) for r, wt in stats.values())
            den = sum(float(dr.sum(wt)[0]) for r, wt in stats.values())
            terms["image_rms"] = math.sqrt(num / max(den, 1.0) / 3.0)
        return terms, g

    def _feature_term(self, pos, R, t, focal):
        """E_F: mean squared distance (px at 512 px height) of the projected feature points from the
        clicked ones, over ``feature_sigma``^2; and the per-point squared distances."""
        fp = dr.gather(mi.Vector3f, pos, self.dr_feature_local)
        fu, fv = self._project(self._to_camera(fp, R, t), focal)
        tu = mi.Float(self.feature_pixels[:, 0].astype(np.float32))
        tv = mi.Float(self.feature_pixels[:, 1].astype(np.float32))
        f_sq = (dr.square(fu - tu) + dr.square(fv - tv)) / (self.scale_px ** 2)
        return dr.sum(f_sq) / len(self.feature_vertices) / self.weights.feature_sigma ** 2, f_sq

    def _coefficient_prior(self, theta):
        """The Mahalanobis part of E_P (Blanz and Vetter 1999, eq. 3; coefficients in standard
        deviations) plus the prior of log focal length around the calibration."""
        L, w = self.layout, self.weights
        e_p = mi.Float(0.0)
        for name, weight in (("shape", w.shape), ("expression", w.expression), ("color", w.texture)):
            if name in L.slices and L[name].stop > L[name].start:
                s = L[name]
                vals = dr.gather(mi.Float, theta, dr.arange(mi.UInt32, s.start, s.stop))
                e_p = e_p + weight * dr.sum(dr.square(vals))
        log_f = self._scalar(theta, L["log_focal"].start)
        return e_p + dr.square(log_f / w.focal)

    def _distance_term(self, neutral):
        """The metric distances between feature points (the capture's tape measurements, mm),
        measured on the face at rest: the identity shape, without expression."""
        length = dr.norm(dr.gather(mi.Vector3f, neutral, self.dr_distance_local[0]) -
                         dr.gather(mi.Vector3f, neutral, self.dr_distance_local[1]))
        return (dr.sum(dr.square((length - self.dr_distance_mm) / self.weights.distance_sigma))
                / len(self.distances))

    def _image_term(self, theta, pos, R, t, focal):
        """E_I, the mean over the photographs; the albedo prior (None for a model with a colour
        model); and per photograph the sample residuals and weights."""
        sp = dr.gather(mi.Vector3f, pos, self.dr_sample_local)
        n = self._normals(pos)
        pc = self._to_camera(sp, R, t)
        nc = mi.Vector3f(*[R[i][0] * n[0] + R[i][1] * n[1] + R[i][2] * n[2] for i in range(3)])
        pcv = mi.Vector3f(*pc)
        view = dr.normalize(-pcv)
        u, v = self._project(pc, focal)
        facing = dr.maximum(dr.dot(nc, view), 0.0)
        albedo, albedo_prior = self._albedo(theta)
        total = mi.Float(0.0)
        stats = {}
        for key in self.image_names:
            colour = self._shade(theta, key, albedo, nc, view, pcv, t)
            observed, inside = self._bilinear(self.dr_images[key], u, v)
            weight = self.dr_visible[key] * dr.select(inside, 1.0, 0.0) * dr.clip((facing - 0.1) * 5.0, 0.0, 1.0)
            residual = dr.squared_norm(colour - observed)
            wsum = dr.maximum(dr.sum(weight), 1.0)
            total = total + dr.sum(weight * residual) / wsum / self.weights.image_sigma ** 2
            stats[key] = (residual, weight)
        return total / len(self.image_names), albedo_prior, stats

    def _normals(self, pos):
        """Model-space unit normals of the samples from their one-rings (area weighted)."""
        a = dr.gather(mi.Vector3f, pos, self.dr_corners[0])
        b = dr.gather(mi.Vector3f, pos, self.dr_corners[1])
        cc = dr.gather(mi.Vector3f, pos, self.dr_corners[2])
        fn = dr.cross(b - a, cc - a) * self.dr_slot_valid
        return dr.normalize(mi.Vector3f(dr.block_sum(fn.x, self.degree), dr.block_sum(fn.y, self.degree),
                                        dr.block_sum(fn.z, self.degree)))

    def _albedo(self, theta):
        """The samples' albedo: the colour model's (texture coefficients beta), or the fitted
        per-vertex albedo with its prior, the squared deviation from its mean."""
        if self.model.has_texture:
            alb = self.dr_color_mean
            s = self.layout["color"].start
            for k in range(self.model.color_dim):
                alb = alb + self.dr_color_basis[k] * self._scalar(theta, s + k)
            return dr.gather(mi.Vector3f, alb, dr.arange(mi.UInt32, self.n_samples)), None
        s = self.layout["albedo"].start
        albedo = mi.Vector3f(*[dr.gather(mi.Float, theta, 3 * self.dr_sample_vertex + (s + k)) for k in range(3)])
        mean_albedo = mi.Vector3f(*[dr.sum(albedo[k]) / self.n_samples for k in range(3)])
        return albedo, self.weights.albedo * dr.sum(dr.squared_norm(albedo - mean_albedo)) / self.n_samples

    def _shade(self, theta, key: str, albedo, nc, view, pcv, t):
        """Phong colour of the samples in photograph ``key`` (Blanz and Vetter 1999, sec. 4): ambient
        + directed light with cast shadow + specular lobe, then colour contrast, gain and offset."""
        L = self.layout
        el, az = self._block(theta, f"{key}.light_angles")
        ld = mi.Vector3f(dr.cos(el) * dr.sin(az), -dr.sin(el), -dr.cos(el) * dr.cos(az))
        lc = mi.Color3f(*self._block(theta, f"{key}.light_color"))
        if key == "point" and math.isfinite(self.light_distance):
            # the lamp at its calibrated distance in the fitted direction: per-point
            # direction and inverse-square falloff (relative to the face centre)
            to_light = mi.Vector3f(*t) + self.light_distance * ld - pcv
            dist2 = dr.squared_norm(to_light)
            ld = to_light / dr.sqrt(dist2)
            lc = lc * (self.light_distance ** 2 / dist2)
        amb = mi.Color3f(*self._block(theta, f"{key}.ambient"))
        ks = self._scalar(theta, L[f"{key}.specular"].start)
        contrast = self._scalar(theta, L[f"{key}.contrast"].start)
        gain = mi.Color3f(*self._block(theta, f"{key}.gain"))
        offset = mi.Color3f(*self._block(theta, f"{key}.offset"))
        grey = getattr(self, "greyscale", False)  # issue 12: set by fit.fit_measurement for grey photographs
        if grey:  # one light colour, ambient, gain and offset: channel 0 of each block, so none can tint
            lc, amb, gain, offset = (mi.Color3f(c.x) for c in (lc, amb, gain, offset))
        shadow = self.dr_shadow if key == "point" else 1.0
        ndl = dr.dot(nc, ld)
        refl = 2 * ndl * nc - ld
        spec = ks * dr.power(dr.maximum(dr.dot(refl, view), 0.0), PHONG_EXPONENT)
        lit = shadow * dr.select(ndl > 0, 1.0, 0.0)
        colour = albedo * (amb + lc * dr.maximum(ndl, 0.0) * shadow) + lc * spec * lit
        lum = LUMINANCE[0] * colour.x + LUMINANCE[1] * colour.y + LUMINANCE[2] * colour.z
        if grey:  # the photograph's grey value against the rendering's luminance (contrast plays no part)
            return mi.Color3f(gain.x * lum + offset.x)
        colour = lum + contrast * (colour - lum)
        return gain * colour + offset
