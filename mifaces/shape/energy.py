"""The energy of a shape fit, ``E = E_I + E_F + E_P`` (paper sec. 4.2), on the
Dr.Jit side and differentiable (reverse mode).

* ``E_I``: squared RGB differences between the photograph and a Phong
  rendering of the model in the model's domain -- sample vertices projected
  into the image (:mod:`mifaces.shape.projection`), the image sampled
  bilinearly there, compared with ambient + directed light (cast shadow) + a
  specular lobe, then colour contrast, gain and offset (Blanz and Vetter 1999,
  sec. 4; :mod:`mifaces.shape.shading`); one term per photograph.
* ``E_F``: squared image distances between the model's feature points and the
  clicked ones.
* ``E_P``: the Mahalanobis norm of the coefficients (Blanz and Vetter 1999,
  eq. 3), log focal length around the calibration, the capture's metric
  distances on the identity shape, and for a model without colour model the
  per-vertex albedo's deviation from its mean.

The model enters through the rows a sample set needs
(:class:`~mifaces.shape.sampled_model.SampledModel`), the camera through
:mod:`mifaces.shape.projection`, the photographs' lighting through :mod:`mifaces.shape.shading`. One evaluation (E, its terms and dE/dtheta) is a few kernels, frozen
with ``dr.freeze`` and reused across iterations and photographs (see :class:`Energy`);
``validation/bench_shape_kernels.py`` counts them.
"""

from __future__ import annotations

import copy
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..runtime.arrays import device_array
from .layout import Layout
from .projection import bilinear, moved, project
from .layout import adjacency as triangle_adjacency
from .result import Weights
from .sampled_model import SAMPLES, SampledModel, lanes
from .shading import directed, lamp, phong, response, towards_light
from .targets import FRONTAL, blurred


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
    light_distance : dict
        Per photograph lit by a directed light (:func:`~mifaces.shape.shading.directed`): the
        distance (mm) of its lamp from the face centre; inf (or absent) for a directional light.
    adjacency : (N, D) int array, optional
        The model's vertex-triangle adjacency (:func:`~mifaces.shape.layout.adjacency`), if
        already at hand.
    freeze : bool
        Replay the kernels of an evaluation (``dr.freeze``) instead of tracing it again, while
        the arrays keep their sizes (recorded anew per sample set).
    views : dict, optional
        Photographs taken by another calibrated camera of the same shot: key -> ``(camera, A, b)``,
        that camera and the map ``x -> A x + b`` from ``camera``'s frame (the fit's) to its own.
        The face is shaded in the fit's frame, seen from that camera's centre, and projected
        through it; the others are ``camera``'s.
    view_features : sequence of (camera, A, b, vertices, pixels)
        Feature points clicked in another camera's photograph of the shot (its frame as in
        ``views``): they join E_F, in that camera's pixels.

    Notes
    -----
    One evaluation is a handful of kernels, one per array width (the needed vertices, the
    samples, the feature points, the distances, the prior's coefficients), forward and
    backward. Every parameter is gathered from ``theta`` at the width of the array it enters
    (:func:`~mifaces.shape.sampled_model.lanes`), never broadcast from a single value, so its
    gradient is a scatter-add inside the backward kernel instead of a reduction of its own; the sums of E are
    scatter-adds into one accumulator (:attr:`slots`), read back with the gradient once per
    evaluation. What differs between the photographs of a capture (the number of feature
    points and distances, the lamp's distance) enters as opaque values, so a second
    photograph of the same size reuses the first one's kernels. The Dr.Jit arrays are the
    attributes named ``dr_*`` and the sample set's (:meth:`arrays`): the frozen evaluation takes
    them as its input and reads them through :meth:`bound`.
    """

    def __init__(self, model, camera, layout: Layout, weights: Weights, images: dict, feature_vertices,
                 feature_pixels, distances, centre, light_distance: dict | None = None, freeze: bool = True,
                 adjacency=None, views: dict | None = None, view_features=()):
        self.model, self.camera, self.layout, self.weights = model, camera, layout, weights
        self.views, self.view_features = dict(views or {}), list(view_features)
        self.n_features = len(feature_vertices) + sum(len(view[3]) for view in self.view_features)
        self.images = images
        self.image_names = list(images)
        self.feature_vertices, self.feature_pixels = feature_vertices, feature_pixels
        self.distances = distances
        self.distance_vertices = np.array([[a, b] for a, b, _ in distances], np.int64).reshape(-1, 2)
        self.centre = centre
        self.light_distance = {key: float((light_distance or {}).get(key, math.inf))
                               for key in self.image_names if directed(key)}
        self.scale_px = camera.height / 512.0  # px per "512-px pixel"
        self.adjacency = triangle_adjacency(model.triangles, model.vertex_count) if adjacency is None else adjacency
        # accumulator slots: per image (sum of w r, sum of w), then the other sums of E
        self.slots = {name: i for i, name in enumerate(
            [f"{k}.{s}" for k in self.image_names for s in ("num", "den")] +
            ["features", "distances", "prior", "albedo", "albedo.r", "albedo.g", "albedo.b"])}
        # opaque indices: a literal index into an evaluated array would be read on the host
        self.dr_index = [dr.opaque(mi.UInt32, i) for i in range(max(len(self.slots), 8))]
        self.dr_fade_index = [dr.opaque(mi.UInt32, layout.size + k) for k in range(2)]
        # per measurement, opaque: the kernels do not depend on them
        self.dr_inv_features = dr.opaque(mi.Float, 1.0 / self.n_features)
        self.dr_inv_distances = dr.opaque(mi.Float, 1.0 / max(len(distances), 1))
        self.dr_light_distance = {key: dr.opaque(mi.Float, d if math.isfinite(d) else 0.0)
                                  for key, d in self.light_distance.items()}
        self.dr_feature_u = device_array(np.float32, np.asarray(feature_pixels)[:, 0])
        self.dr_feature_v = device_array(np.float32, np.asarray(feature_pixels)[:, 1])
        self.dr_view_feature_u = [device_array(np.float32, np.asarray(view[4])[:, 0]) for view in self.view_features]
        self.dr_view_feature_v = [device_array(np.float32, np.asarray(view[4])[:, 1]) for view in self.view_features]
        if len(distances):  # (an empty array cannot enter a frozen function)
            self.dr_distance_mm = device_array(np.float32, [d for _, _, d in distances])
        self._prior_weights()
        self.sampled = None  # the sample set (set_samples)
        # the widths are literals of the recorded kernels: a new sample set records anew
        self._frozen = dr.freeze(self._evaluate, enabled=freeze, warn_after=20,
                                 state_fn=lambda arrays, *args: self.widths(arrays))

    def _prior_weights(self):
        """Indices into theta and weights of the quadratic prior: the Mahalanobis norms of the
        coefficients (Blanz and Vetter 1999, eq. 3; coefficients in standard deviations) and log
        focal length around the calibration (standard deviation ``Weights.focal``)."""
        L, w = self.layout, self.weights
        index, weight = [L["log_focal"].start], [1.0 / w.focal ** 2]
        for name, value in (("shape", w.shape), ("expression", w.expression), ("color", w.texture)):
            if name in L.slices:
                index.extend(range(L[name].start, L[name].stop))
                weight.extend([value] * (L[name].stop - L[name].start))
        self.dr_prior_index = device_array(np.uint32, index)
        self.dr_prior_weight = device_array(np.float32, weight)

    # ---- the sample set and the image level ---------------------------------------------------
    def set_samples(self, samples: np.ndarray):
        """The sample vertices ``samples`` of E_I: the model rows they, their one-rings, the feature
        points and the metric distances need on the Dr.Jit side (:class:`SampledModel`); every
        sample visible and lit."""
        vertices = {"features": self.feature_vertices, "distances.0": self.distance_vertices[:, 0],
                    "distances.1": self.distance_vertices[:, 1],
                    **{f"view.{i}": view[3] for i, view in enumerate(self.view_features)}}
        self.sampled = SampledModel(self.model, self.adjacency, samples, vertices)
        self.set_visibility(np.ones(len(samples), np.float32))

    def arrays(self) -> dict:
        """The Dr.Jit arrays of E: the attributes named ``dr_*``, and the sample set's
        (:meth:`SampledModel.arrays`) as ``'sampled'``; the input of a frozen evaluation."""
        return {**{k: v for k, v in vars(self).items() if k.startswith("dr_")}, "sampled": self.sampled.arrays()}

    def bound(self, arrays: dict) -> Energy:
        """This energy reading ``arrays`` (:meth:`arrays`' layout) in place of its own: what a frozen
        function evaluates."""
        energy = copy.copy(self)
        vars(energy).update({k: v for k, v in arrays.items() if k != "sampled"})
        energy.sampled = self.sampled.bound(arrays["sampled"])
        return energy

    def widths(self, arrays: dict) -> tuple:
        """What the recorded kernels of :meth:`arrays` hold as literals: the needed rows and the
        samples (a new sample set records anew)."""
        return dr.width(arrays["sampled"]["dr_mean"]), self.sampled.n_samples

    def set_visibility(self, seen: np.ndarray, lit: dict | None = None, seen_by: dict | None = None):
        """Per sample: seen by the camera (every image but those of :attr:`views`, each seen as
        ``seen_by`` says), and per photograph with a directed light
        (:func:`~mifaces.shape.shading.directed`), lit by its lamp (0 or 1; 1 for every sample where
        ``lit`` or ``seen_by`` lacks it)."""
        self.dr_visible = device_array(np.float32, seen)
        ones = np.ones(len(seen), np.float32)
        self.dr_visible_by = {key: device_array(np.float32, (seen_by or {}).get(key, ones)) for key in self.views}
        self.dr_shadow = {key: device_array(np.float32, (lit or {}).get(key, ones))
                          for key in self.light_distance}

    def set_level(self, blur: float):
        """The photographs blurred by ``blur`` px at 512 px image height, on the Dr.Jit side."""
        self.dr_images = {}
        for key, image in self.images.items():
            b = blurred(image, blur * self.scale_px)
            self.dr_images[key] = device_array(np.float32, b)

    # ---- parameters and pose -------------------------------------------------------------------
    def _block(self, theta, name: str, width: int):
        """Parameter block ``name`` of ``theta`` on ``width`` lanes (:func:`~mifaces.shape.sampled_model.lanes`)."""
        s = self.layout[name]
        return [lanes(theta, i, width) for i in range(s.start, s.stop)]

    def _rotation(self, theta, width: int):
        """Rows of ``R0 R_y R_x R_z`` on ``width`` lanes (row-major 3x3 list)."""
        yaw, pitch, roll = self._block(theta, "rotation", width)
        cy, sy, cp, sp, cr, sr = dr.cos(yaw), dr.sin(yaw), dr.cos(pitch), dr.sin(pitch), dr.cos(roll), dr.sin(roll)
        # R_y R_x R_z, expanded
        r = [[cy * cr + sy * sp * sr, -cy * sr + sy * sp * cr, sy * cp],
             [cp * sr, cp * cr, -sp],
             [-sy * cr + cy * sp * sr, sy * sr + cy * sp * cr, cy * cp]]
        return [[float(FRONTAL[i, i]) * r[i][j] for j in range(3)] for i in range(3)]

    def _pose(self, theta, width: int):
        """Rotation, translation and focal-length factor of ``theta`` on ``width`` lanes."""
        return (self._rotation(theta, width), self._block(theta, "translation", width),
                dr.exp(lanes(theta, self.layout["log_focal"].start, width)))

    def _to_camera(self, p, R, t):
        """Camera-space coordinates ``R (p - c) + t`` of model-space points ``p`` (3 Floats)."""
        c = [float(x) for x in self.centre]
        q = [p[0] - c[0], p[1] - c[1], p[2] - c[2]]
        return [R[i][0] * q[0] + R[i][1] * q[1] + R[i][2] * q[2] + t[i] for i in range(3)]

    # ---- the energy ----------------------------------------------------------------------------
    def evaluate(self, theta_np: np.ndarray, feature_weight: float, image_weight: float, grad: bool = True):
        """E and its terms for parameters ``theta_np``; with ``grad``, also dE/dtheta (numpy).

        ``feature_weight`` multiplies :attr:`Weights.feature`; ``image_weight`` E_I (0: E_I is not
        evaluated). Returns the terms ``E, E_I, E_F, E_P, E_D`` (E_D, the metric distances, is
        part of E_P), ``feature_rms_px`` and, with the image term, ``image_rms``; and the gradient.
        """
        # theta, then the weights that change every iteration while E_F fades: one upload, data,
        # so kernels stay cached
        size = len(theta_np)
        inputs = device_array(np.float32, np.concatenate([theta_np, [feature_weight * self.weights.feature,
                                                                     image_weight]]))
        out = self._frozen(self.arrays(), inputs, image_weight > 0, grad)
        values = np.asarray(out[0], np.float64)
        g = np.asarray(out[1], np.float64)[:size] if grad else None
        return self.terms(values, image_weight > 0), g

    def image_sums(self, theta_np: np.ndarray) -> dict:
        """Per photograph, E_I's sums at ``theta`` (traced once, not frozen: for a fit's end):
        key -> (sum of weighted squared RGB residuals, sum of weights)."""
        theta = device_array(np.float32, theta_np)
        acc = dr.zeros(mi.Float, len(self.slots))
        self._image_sums(acc, theta, self.sampled.positions(theta, self.layout["shape"].start))
        sums = np.asarray(acc, np.float64)
        return {key: (sums[self.slots[f"{key}.num"]], sums[self.slots[f"{key}.den"]]) for key in self.image_names}

    def terms(self, values, use_image: bool) -> dict:
        """The terms (see :meth:`evaluate`) of the packed values of :meth:`energy`."""
        terms = dict(zip(("E", "E_I", "E_F", "E_P", "E_D"), (float(v) for v in values[:5])))
        terms["feature_rms_px"] = math.sqrt(max(values[5], 0.0) / self.n_features) * self.scale_px
        if use_image:
            terms["image_rms"] = math.sqrt(values[6] / max(values[7], 1.0) / 3.0)
        return terms

    def _evaluate(self, arrays: dict, inputs, use_image: bool, grad: bool):
        """The packed terms (see :meth:`energy`) and, with ``grad``, dE/d(inputs), evaluated, for
        ``inputs``: theta followed by the fading weights ``[feature, image]``; the Dr.Jit arrays
        read from ``arrays`` (the input of the frozen function)."""
        energy_of = self.bound(arrays)
        if grad:
            dr.enable_grad(inputs)
        fade = [dr.gather(mi.Float, inputs, i) for i in energy_of.dr_fade_index]
        energy, packed = energy_of.energy(inputs, fade, use_image)
        if not grad:
            dr.eval(packed)
            return (packed,)
        dr.backward(energy)
        g = dr.grad(inputs)
        dr.eval(packed, g)
        return packed, g

    def energy(self, theta, fade, use_image: bool):
        """E (differentiable, one value) for parameters ``theta`` and fading weights ``fade``
        (``[feature, image]``, single values), and the detached terms packed as ``E, E_I, E_F, E_P, E_D, sum of
        squared feature distances, sum of weighted image residuals, sum of image weights``."""
        acc = dr.zeros(mi.Float, len(self.slots))
        pos = self.sampled.positions(theta, self.layout["shape"].start)
        self._feature_sums(acc, theta, pos)
        self._prior_sums(acc, theta)
        if len(self.distances):
            self._distance_sums(acc, theta)
        if use_image:
            self._image_sums(acc, theta, pos)

        def slot(name):
            return dr.gather(mi.Float, acc, self.dr_index[self.slots[name]])

        w = self.weights
        e_f = slot("features") * self.dr_inv_features / w.feature_sigma ** 2
        e_d = slot("distances") * self.dr_inv_distances / w.distance_sigma ** 2
        # the albedo's squared deviations from its mean, sum |a - mean|^2 = sum |a|^2 - |sum a|^2 / n:
        # both sums accumulate in the samples' kernel (a mean gathered back would split it)
        spread = slot("albedo") - (dr.square(slot("albedo.r")) + dr.square(slot("albedo.g"))
                                   + dr.square(slot("albedo.b"))) * self.sampled.dr_inv_samples
        e_p = slot("prior") + e_d + spread * (w.albedo * self.sampled.dr_inv_samples)
        e_i, num, den = mi.Float(0.0), mi.Float(0.0), mi.Float(0.0)
        if use_image:
            for key in self.image_names:
                e_i = e_i + slot(f"{key}.num") / dr.maximum(slot(f"{key}.den"), 1.0)
                num, den = num + slot(f"{key}.num"), den + slot(f"{key}.den")
            e_i = e_i / (len(self.image_names) * w.image_sigma ** 2)
        energy = fade[1] * e_i + fade[0] * e_f + e_p
        values = (energy, e_i, e_f, e_p, e_d, slot("features"), num, den)
        lane, packed = dr.arange(mi.UInt32, len(values)), mi.Float(0.0)
        for i, value in enumerate(values):
            packed = dr.select(lane == i, dr.detach(value), packed)
        return energy, packed

    def _feature_sums(self, acc, theta, pos):
        """Squared distances (px at 512 px height) of the projected feature points from the clicked
        ones into slot ``features`` (E_F is their mean over ``feature_sigma``^2)."""
        width = len(self.feature_vertices)
        R, t, focal = self._pose(theta, width)
        fp = dr.gather(mi.Vector3f, pos, self.sampled.dr_local["features"])
        fu, fv = project(self._to_camera(fp, R, t), focal, self.camera)
        f_sq = (dr.square(fu - self.dr_feature_u) + dr.square(fv - self.dr_feature_v)) / (self.scale_px ** 2)
        dr.scatter_add(acc, f_sq, dr.full(mi.UInt32, self.slots["features"], width))
        for i, (cam, A, b, vertices, _) in enumerate(self.view_features):  # other cameras' clicks, their pixels
            width = len(vertices)
            R, t, _ = self._pose(theta, width)
            fp = dr.gather(mi.Vector3f, pos, self.sampled.dr_local[f"view.{i}"])
            fu, fv = project(moved(self._to_camera(fp, R, t), A, b), 1.0, cam)
            f_sq = (dr.square(fu - self.dr_view_feature_u[i]) + dr.square(fv - self.dr_view_feature_v[i])) / (
                self.scale_px ** 2)
            dr.scatter_add(acc, f_sq, dr.full(mi.UInt32, self.slots["features"], width))

    def _prior_sums(self, acc, theta):
        """The quadratic prior of E_P (see :meth:`_prior_weights`) into slot ``prior``."""
        values = dr.gather(mi.Float, theta, self.dr_prior_index)
        dr.scatter_add(acc, self.dr_prior_weight * dr.square(values),
                       dr.full(mi.UInt32, self.slots["prior"], dr.width(values)))

    def _distance_sums(self, acc, theta):
        """The metric distances between feature points (the capture's tape measurements, mm),
        measured on the face at rest (the identity shape, without expression): squared errors
        into slot ``distances``."""
        start = self.layout["shape"].start
        a, b = (self.sampled.identity_positions(theta, start, f"distances.{k}") for k in range(2))
        length = dr.norm(a - b)
        dr.scatter_add(acc, dr.square(length - self.dr_distance_mm),
                       dr.full(mi.UInt32, self.slots["distances"], len(self.distances)))

    def _image_sums(self, acc, theta, pos):
        """E_I's sums per photograph (weighted squared residuals and weights) and, for a model
        without colour model, the sums of the albedo prior (see :meth:`energy`)."""
        width = self.sampled.n_samples
        R, t, focal = self._pose(theta, width)
        sp = dr.gather(mi.Vector3f, pos, self.sampled.dr_local[SAMPLES])
        n = self.sampled.normals(pos)
        pc = self._to_camera(sp, R, t)
        nc = mi.Vector3f(*[R[i][0] * n[0] + R[i][1] * n[1] + R[i][2] * n[2] for i in range(3)])
        pcv = mi.Vector3f(*pc)
        view = dr.normalize(-pcv)
        u, v = project(pc, focal, self.camera)
        facing = dr.maximum(dr.dot(nc, view), 0.0)
        albedo = self._albedo(acc, theta)
        for key in self.image_names:
            if key in self.views:  # another camera of the shot: seen from its centre, through its lens
                cam, A, b = self.views[key]
                centre = -np.asarray(A, np.float64).T @ np.asarray(b, np.float64)
                seen_from = dr.normalize(mi.Vector3f(*[float(c) for c in centre]) - pcv)
                uk, vk = project(moved(pc, A, b), 1.0, cam)
                facing_k, visible = dr.maximum(dr.dot(nc, seen_from), 0.0), self.dr_visible_by[key]
            else:
                cam, seen_from, uk, vk, facing_k, visible = None, view, u, v, facing, self.dr_visible
            colour = self._shade(theta, key, albedo, nc, seen_from, pcv, t)
            observed, inside = bilinear(self.dr_images[key], uk, vk, cam or self.camera)
            weight = visible * dr.select(inside, 1.0, 0.0) * dr.clip((facing_k - 0.1) * 5.0, 0.0, 1.0)
            residual = dr.squared_norm(colour - observed)
            dr.scatter_add(acc, weight * residual, dr.full(mi.UInt32, self.slots[f"{key}.num"], width))
            dr.scatter_add(acc, weight, dr.full(mi.UInt32, self.slots[f"{key}.den"], width))

    def _albedo(self, acc, theta):
        """The samples' albedo (:meth:`SampledModel.albedo`); a fitted per-vertex albedo's squared
        norms and channel sums go into slots ``albedo`` and ``albedo.r/g/b`` (the prior on its
        deviations from its mean)."""
        width, has_texture = self.sampled.n_samples, self.model.has_texture
        albedo = self.sampled.albedo(theta, self.layout["color" if has_texture else "albedo"].start)
        if not has_texture:
            dr.scatter_add(acc, dr.squared_norm(albedo), dr.full(mi.UInt32, self.slots["albedo"], width))
            for k, channel in enumerate("rgb"):
                dr.scatter_add(acc, albedo[k], dr.full(mi.UInt32, self.slots[f"albedo.{channel}"], width))
        return albedo

    def _shade(self, theta, key: str, albedo, nc, view, pcv, t):
        """The samples' value in photograph ``key``: its lighting gathered from ``theta`` and rendered
        as :mod:`mifaces.shape.shading` says (Blanz and Vetter 1999, sec. 4), its lamp at its
        calibrated distance where it has one."""
        L, width = self.layout, self.sampled.n_samples

        def block(name):
            return self._block(theta, f"{key}.{name}", width)

        ld, lc = towards_light(*block("light_angles")), mi.Color3f(*block("light_color"))
        if math.isfinite(self.light_distance.get(key, math.inf)):
            ld, lc = lamp(ld, lc, self.dr_light_distance[key], t, pcv)
        amb = mi.Color3f(*block("ambient"))
        ks = lanes(theta, L[f"{key}.specular"].start, width)
        contrast = lanes(theta, L[f"{key}.contrast"].start, width)
        gain, offset = mi.Color3f(*block("gain")), mi.Color3f(*block("offset"))
        grey = getattr(self, "greyscale", False)  # issue 12: set by fit.fit_measurement for grey photographs
        if grey:  # one light colour, ambient, gain and offset: channel 0 of each block, so none can tint
            lc, amb, gain, offset = (mi.Color3f(c.x) for c in (lc, amb, gain, offset))
        colour = phong(albedo, nc, view, ld, lc, amb, ks, self.dr_shadow.get(key, 1.0))
        return response(colour, contrast, gain, offset, grey)
