"""The optimiser of one shape fit (paper sec. 4.2): Adam (Kingma and Ba 2015)
on parameters scaled to natural units, in place of the paper's stochastic
Newton method -- landmark-only steps first, then coarse-to-fine image levels
with a geometrically decaying step; the sample vertices drawn per level, and
visibility and cast shadows by Mitsuba ray casting on the full current mesh,
recomputed every ``visibility_interval`` iterations (the paper re-computes its
shadow map every 1000 iterations)."""

from __future__ import annotations

import math
import weakref

import drjit as dr
import mitsuba as mi
import numpy as np
from scipy.spatial import cKDTree

from ..capture.camera import relative_pose
from ..model.geometry import rotation_matrix
from ..model.mesh import mitsuba_mesh
from ..runtime.status import DIVERGED, NOT_CONVERGED
from .adam import COLUMNS, DeviceAdam
from .energy import Energy
from .shading import POINT, directed
from .layout import Layout, adjacency
from .result import ShapeFit, ShapeOptions, ShapeSchedule, Weights
from .targets import (FRONTAL, light_direction, metric_distances, normalised, rotation_centre, start_light,
                      start_translation, triangulated_translation)

#: Steps between the host's reads of the fit's terms (the history's spacing).
CHUNK = 10
#: Sample vertices are kept this far (mm) from the mesh's open border.
BORDER_MARGIN = 6.0


def distance_from_border(model) -> np.ndarray:
    """Distance (mm, on the mean shape) of every vertex from the nearest vertex on an open
    border of the mesh (an edge used by one triangle); inf for a closed mesh."""
    t = np.asarray(model.triangles, np.int64)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    n = model.vertex_count
    keys, counts = np.unique(edges[:, 0] * n + edges[:, 1], return_counts=True)  # one int per edge: fast
    single = keys[counts == 1]
    border = np.unique(np.concatenate([single // n, single % n]))
    if len(border) == 0:
        return np.full(model.vertex_count, np.inf)
    return cKDTree(model.shape_mean[border]).query(model.shape_mean)[0]


def sample_normals(vertices: np.ndarray, triangles: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """Unit normals (float64) of the vertices whose adjacent triangles are the rows of ``ring``
    (``(S, D)``, padded with -1): the area-weighted mean of the face normals, as
    :func:`~mifaces.model.geometry.vertex_normals` gives them on the whole mesh."""
    tri = triangles[np.where(ring >= 0, ring, 0)]  # (S, D, 3)
    v = np.asarray(vertices, np.float64)
    a, b, c = v[tri[..., 0]], v[tri[..., 1]], v[tri[..., 2]]
    n = np.sum(np.cross(b - a, c - a) * (ring >= 0)[..., None], axis=1)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0, n / np.maximum(length, 1e-30), 0.0).astype(np.float32).astype(np.float64)


class _ModelArrays:
    """What every fit of one model needs and no fit changes, computed once per model: the
    vertices' distance from the open border, the vertex-triangle adjacency, and the scaled
    shape and expression bases in float32 (``(3N, K)``, columns ``basis * sqrt(variance)``) for
    the full mesh's positions at every visibility update (a float32 matrix-vector product; the
    model's own float64 one converts the whole basis each time)."""

    _cache: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def __init__(self, model):
        self.border = distance_from_border(model)
        self.adjacency = adjacency(model.triangles, model.vertex_count)
        columns = [model.shape_basis * np.sqrt(model.shape_variance).astype(np.float32)]
        if model.has_expressions:
            columns.append(model.expression_basis * np.sqrt(model.expression_variance).astype(np.float32))
        self.basis = np.ascontiguousarray(np.concatenate(columns, axis=1), np.float32)
        self.mean = model.shape_mean.astype(np.float64).ravel()

    @classmethod
    def of(cls, model) -> _ModelArrays:
        arrays = cls._cache.get(model)
        if arrays is None:
            arrays = cls._cache[model] = cls(model)
        return arrays


class Fitter:
    """One fit: the start, the sample sets, visibility, and Adam over the schedule's stages."""

    def __init__(self, model, camera, images: dict, targets, weights: Weights, schedule: ShapeSchedule, rng,
                 light_world=None, fit_focal=True, initial=None, fixed=(), distances=(),
                 facing_min: float = ShapeOptions.facing_min, views: dict | None = None):
        """``views``: image key -> ``(camera, vertices, pixels)`` of each photograph another camera
        of the shot took: that camera, and the model vertices and pixels of the feature points clicked
        in it (:class:`~mifaces.shape.energy.Energy`'s ``views`` and ``view_features``)."""
        self.model, self.camera, self.weights, self.schedule, self.rng = model, camera, weights, schedule, rng
        self.views = {key: (view[0], *relative_pose(camera, view[0])) for key, view in (views or {}).items()}
        self.fit_focal = fit_focal
        self.facing_min = float(facing_min)  # ShapeOptions.facing_min
        _, self.feature_vertices, self.feature_pixels = targets
        self.scale_px = camera.height / 512.0  # px per "512-px pixel"
        self.images, self.image_scale = {}, {}
        for key, pixels in images.items():
            self.images[key], self.image_scale[key] = normalised(pixels)
        self.image_names = list(self.images)
        self.layout = Layout(model, self.image_names)
        self.centre = rotation_centre(model)
        self.initial_blocks = dict(initial or {})
        unknown = [k for k in list(self.initial_blocks) + list(fixed) if k not in self.layout.slices]
        if unknown:
            raise ValueError(f"unknown parameter block(s) {unknown}; blocks: {list(self.layout.slices)}")
        self.fixed = tuple(fixed)
        used = np.zeros(model.vertex_count, bool)
        used[model.triangles.ravel()] = True
        # samples keep away from the mesh's open border, whose pixels mix face and background
        self.arrays = _ModelArrays.of(model)
        inner = self.arrays.border > BORDER_MARGIN
        self.candidates = np.flatnonzero(used & (model.vertex_regions() != 0) & inner)
        if len(self.candidates) < 100:
            self.candidates = np.flatnonzero(used)
        view_features = [(view, *relative_pose(camera, view), vertices, pixels)
                         for view, vertices, pixels in (views or {}).values()]
        triangulated = triangulated_translation(model, camera, self.feature_vertices, self.feature_pixels,
                                                self.centre, view_features) if view_features else None
        self.start_translation = triangulated if triangulated is not None else start_translation(
            model, camera, self.feature_vertices, self.feature_pixels, self.centre)
        #: per photograph with a directed light (:func:`~mifaces.shape.shading.directed`): its start
        #: angles and its lamp's distance (mm) from the face centre, infinite (a directional light)
        #: unless the capture's calibration gives the lamp's position
        if light_world is not None and not isinstance(light_world, dict):
            light_world = {POINT: light_world}
        self.light_angles, self.light_distance = {}, {}
        for key in filter(directed, self.image_names):
            position = (light_world or {}).get(key)
            el, az, distance = (0.0, 0.0, math.inf) if position is None else start_light(
                camera, self.start_translation, np.asarray(position, np.float64))
            self.light_angles[key], self.light_distance[key] = (el, az), distance
        self.energy = Energy(model, camera, self.layout, weights, self.images, self.feature_vertices,
                             self.feature_pixels, metric_distances(distances, model), self.centre,
                             self.light_distance, adjacency=self.arrays.adjacency, views=self.views,
                             view_features=view_features)
        self._scene = None  # the Mitsuba scene of the full mesh, its positions updated per visibility update

    def initial(self) -> np.ndarray:
        """Frontal view of the mean face placed on the feature points (paper: 'default values
        defining a frontal view and frontal illumination'), lights from the calibration."""
        L, m = self.layout, self.model
        theta = np.zeros(L.size)
        theta[L["translation"]] = self.start_translation
        for image in self.image_names:
            lit = directed(image)
            theta[L[f"{image}.light_angles"]] = self.light_angles.get(image, (0.0, 0.0))
            theta[L[f"{image}.light_color"]] = 0.8 if lit else 0.0
            theta[L[f"{image}.ambient"]] = 0.1 if lit else 1.0
            theta[L[f"{image}.specular"]] = 0.05 if lit else 0.0
            theta[L[f"{image}.contrast"]] = 1.0
            theta[L[f"{image}.gain"]] = 1.0
        if not m.has_texture:
            theta[L["albedo"]] = np.tile([0.55, 0.42, 0.36], m.vertex_count)
        for name, value in self.initial_blocks.items():
            theta[L[name]] = np.broadcast_to(np.asarray(value, np.float64), (L[name].stop - L[name].start,))
        return theta

    def set_samples(self, count: int):
        """Draw ``count`` sample vertices for the image term and hand them to the energy."""
        count = min(count, len(self.candidates))
        self.samples = np.sort(self.rng.choice(self.candidates, count, replace=False))
        self.energy.set_samples(self.samples)

    # ---- full mesh, visibility and cast shadows (Mitsuba ray casting) -------------------------
    def vertices_camera(self, theta: np.ndarray) -> np.ndarray:
        """All model vertices in camera space (numpy float64, mm)."""
        m, L = self.model, self.layout
        coefficients = [theta[L["shape"]]] + ([theta[L["expression"]]] if m.has_expressions else [])
        local = self.arrays.basis @ np.concatenate(coefficients).astype(np.float32)
        local = (self.arrays.mean + local).reshape(-1, 3).astype(np.float32).astype(np.float64)
        return (local - self.centre) @ self.rotation(theta).T + theta[L["translation"]]

    def rotation(self, theta: np.ndarray) -> np.ndarray:
        """Model -> camera rotation ``R0 R(yaw, pitch, roll)`` of ``theta``."""
        return FRONTAL @ rotation_matrix(*np.degrees(theta[self.layout["rotation"]]))

    def update_visibility(self, theta: np.ndarray):
        """Camera visibility of the samples and cast shadows of the directed light, by ray casting
        against the current full mesh (``Scene.ray_test``)."""
        L = self.layout
        verts = self.vertices_camera(theta)
        if self._scene is None:
            self._scene = mi.load_dict({"type": "scene", "face": mitsuba_mesh(verts, self.model.triangles)})
            self._scene_params = mi.traverse(self._scene)
        else:  # the same triangles: new positions, the acceleration structure rebuilt
            self._scene_params["face.vertex_positions"] = mi.Float(verts.astype(np.float32).ravel())
            self._scene_params.update()
        scene = self._scene
        p = verts[self.samples]
        n = sample_normals(verts, self.model.triangles, self.arrays.adjacency[self.samples])
        eps = 0.3
        dist = np.linalg.norm(p, axis=1)
        d = -p / dist[:, None]  # towards the camera
        origin = p + eps * n

        # rays towards the camera, towards the shot's other cameras, then towards each directed
        # light's lamp: one ray_test
        origins, directions, lengths = [origin], [d], [np.maximum(dist - 2 * eps, eps)]
        for _, A, b in self.views.values():
            to_view = -A.T @ b - p
            length = np.linalg.norm(to_view, axis=1)
            origins.append(origin), directions.append(to_view / length[:, None])
            lengths.append(np.maximum(length - 2 * eps, eps))
        for key, distance in self.light_distance.items():
            el, az = theta[L[f"{key}.light_angles"]]
            ld = np.broadcast_to(light_direction(el, az), p.shape)
            maxt = np.full(len(p), 1e5)
            if math.isfinite(distance):
                to_light = theta[L["translation"]] + distance * ld - origin
                maxt = np.linalg.norm(to_light, axis=1)
                ld = to_light / maxt[:, None]
            origins.append(origin), directions.append(ld), lengths.append(maxt)
        o, direction = np.concatenate(origins).astype(np.float32), np.concatenate(directions).astype(np.float32)
        ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, k]) for k in range(3)]),
                       mi.Vector3f(*[mi.Float(direction[:, k]) for k in range(3)]))
        ray.maxt = mi.Float(np.concatenate(lengths).astype(np.float32))
        occluded = np.asarray(scene.ray_test(ray), bool).reshape(-1, len(p))
        seen = ~occluded[0] & (np.sum(n * d, axis=1) > self.facing_min)
        seen_by = {key: ~occluded[1 + i] & (np.sum(n * directions[1 + i], axis=1) > self.facing_min)
                   for i, key in enumerate(self.views)}
        lit = {key: ~occluded[1 + len(self.views) + i] for i, key in enumerate(self.light_distance)}
        self.energy.set_visibility(seen, lit, seen_by)
        dr.eval()

    # ---- optimisation ------------------------------------------------------------------------
    def stages(self) -> list[tuple]:
        """``(name, iterations, samples, blur, mask)`` per stage: the landmark-only stage (pose, focal
        length, shape and expression; lighting, colour and texture frozen), then the image levels."""
        L = self.layout
        pose_mask = np.zeros(L.size, bool)
        for name in ("rotation", "translation", "log_focal", "shape", "expression"):
            pose_mask[L[name]] = True
        stages = [("pose", self.schedule.pose_iterations, None, None, pose_mask)]
        if self.image_names:
            for i, (iters, samples, blur) in enumerate(self.schedule.levels):
                stages.append((f"level{i}", int(iters), int(samples), float(blur), np.ones(L.size, bool)))
        return stages

    def run(self, progress_bar=None, lr=(0.1, 0.01), visibility_interval: int = 50):
        """Adam on ``theta / unit`` over :meth:`stages`, on the Dr.Jit side (:class:`DeviceAdam`):
        the host reads the steps' terms every :data:`CHUNK` steps and theta at each visibility
        update (every ``visibility_interval`` steps of an image level, a multiple of CHUNK).

        Returns ``(theta, terms, history, iterations, status, message)``; ``status`` is None unless
        the energy or its gradient became non-finite (``'diverged'``): then theta is the last
        finite one and ``iterations`` the steps made before.
        """
        L, w = self.layout, self.weights
        theta = self.initial()
        units = self.layout.units.copy()
        if not self.fit_focal:
            units[L["log_focal"]] = 0.0
        for name in self.fixed:
            units[L[name]] = 0.0
        nonnegative = np.zeros(L.size, bool)
        for key in self.image_names:
            for name in ("light_color", "ambient", "specular", "contrast", "gain"):
                nonnegative[L[f"{key}.{name}"]] = True
        stages = self.stages()
        image_total = sum(s[1] for s in stages[1:])
        history, terms, it_total, image_done = [], {}, 0, 0
        adam = DeviceAdam(self.energy)
        for name, iters, samples, blur, mask in stages:
            self.set_samples(100 if samples is None else samples)
            if samples is not None:
                self.energy.set_level(blur)
                self.update_visibility(theta)
            table = self._step_table(iters, samples is not None, image_done, image_total, lr)
            adam.start(theta, units * mask, nonnegative, table)
            done = 0
            while done < iters:
                if samples is not None and done > 0 and done % visibility_interval == 0:
                    self.update_visibility(adam.read()[0])
                end = min(iters, (done // CHUNK + 1) * CHUNK)
                if samples is not None:  # a visibility update falls on the start of a chunk
                    end = min(end, (done // visibility_interval + 1) * visibility_interval)
                for _ in range(done, end):
                    adam.step(samples is not None)
                theta, packed, failed = adam.read()
                steps = end - done if not failed else max(failed - 1 - done, 0)
                for it in range(done, done + steps):
                    if it % 10 == 0 or it == iters - 1:
                        history.append({"iteration": it_total + it + 1 - done, "stage": name,
                                        **self.energy.terms(packed[it], samples is not None)})
                it_total += steps
                if samples is not None:
                    image_done += steps
                if failed:
                    terms = self.energy.terms(packed[failed - 1], samples is not None)
                    return theta, terms, history, it_total, DIVERGED, f"non-finite energy or gradient in {name}"
                terms = self.energy.terms(packed[end - 1], samples is not None)
                done = end
                if progress_bar is not None:
                    progress_bar.update(steps)
                    progress_bar.set_postfix(stage=name, E=f"{terms['E']:.3g}", lm=f"{terms['feature_rms_px']:.2f}px")
        use_image = bool(self.image_names and self.schedule.levels)
        if use_image:
            self.update_visibility(theta)
        terms, _ = self.energy.evaluate(theta, w.feature_final / max(w.feature, 1e-12), 1.0 if use_image else 0.0,
                                        grad=False)
        return theta, terms, history, it_total, None, ""

    def result(self, theta, name, terms, history, iterations, greyscale=False) -> ShapeFit:
        """The :class:`ShapeFit` of parameters ``theta`` (status still open): vertices, pose and
        per-image lighting, with the gain and offset back in the photograph's units; for greyscale
        photographs the tied colour blocks' one value (channel 0) in every channel."""
        L, model, camera = self.layout, self.model, self.camera
        finite = np.all(np.isfinite(theta))
        verts_c = self.vertices_camera(theta) if finite else np.full((model.vertex_count, 3), np.nan)

        def block(key, name):
            value = theta[L[f"{key}.{name}"]]
            return np.full_like(value, value[0]) if greyscale and len(value) == 3 else value.copy()

        light = {}
        for key in self.image_names:
            el, az = theta[L[f"{key}.light_angles"]]
            scale = self.image_scale[key]
            light[key] = {"direction": light_direction(el, az), "color": block(key, "light_color"),
                          "ambient": block(key, "ambient"), "specular": float(theta[L[f"{key}.specular"]][0]),
                          "contrast": 1.0 if greyscale else float(theta[L[f"{key}.contrast"]][0]),
                          "gain": block(key, "gain") * scale, "offset": block(key, "offset") * scale}
        rot = self.rotation(theta)
        focal = math.exp(theta[L["log_focal"]][0]) * np.array([camera.fx, camera.fy])
        return ShapeFit(
            measurement=name, status=NOT_CONVERGED,
            vertices_world=camera.to_world(verts_c).astype(np.float32), vertices_camera=verts_c.astype(np.float32),
            coefficients=theta[L["shape"]].copy(),
            expression=theta[L["expression"]].copy(),
            color=theta[L["color"]].copy() if model.has_texture else None,
            albedo=theta[L["albedo"]].reshape(-1, 3).astype(np.float32) if "albedo" in L.slices else None,
            rotation=rot, translation=theta[L["translation"]] - rot @ self.centre,
            yaw_pitch_roll=np.degrees(theta[L["rotation"]]), focal_length=focal, light=light, loss=terms,
            iterations=iterations, seconds=0.0, history=history)

    def _step_table(self, iters: int, image: bool, image_done: int, image_total: int, lr) -> np.ndarray:
        """Per step of a stage (:data:`~mifaces.shape.adam.COLUMNS`): the feature term's weight
        (fading over the image levels' first ``Weights.feature_fade``), the image term's, Adam's
        step size (decaying geometrically from ``lr[0]`` to ``lr[1]`` over the image levels) and its
        bias corrections ``1 - beta^k``."""
        w = self.weights
        table = np.zeros((iters, COLUMNS))
        for it in range(iters):
            if not image:
                fw, iw, rate = 1.0, 0.0, lr[0]
            else:
                frac = (image_done + it) / max(image_total, 1)
                fade = min(frac / max(w.feature_fade, 1e-9), 1.0)
                fw = (1 - fade) * 1.0 + fade * (w.feature_final / max(w.feature, 1e-12))
                iw, rate = 1.0, lr[0] * (lr[1] / lr[0]) ** frac
            k = it + 1
            table[it] = (fw * w.feature, iw, rate, 1 - DeviceAdam.beta1 ** k, 1 - DeviceAdam.beta2 ** k)
        return table
