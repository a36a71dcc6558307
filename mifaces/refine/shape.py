"""Shape beyond the model: the fitted faces refined by a per-vertex
displacement, by differentiable rendering against the photographs.

A morphable model spans smooth, average faces; a mole, a scar, an asymmetric
cheek lie outside its span and the model fit (:mod:`mifaces.shape`) leaves
them out. :func:`refine_shape` starts from the fitted faces ``W_k`` (world
frame, mm, one per measurement k) and the fitted BRDF, and minimises

    E(h) = Σ_k 1/|M_k| Σ_{p ∈ M_k} Σ_c ψ_ε((I_k(W_k + h N_k)[p, c] - s J_k[p, c]) / μ_k),

the image loss of :mod:`mifaces.refine.photograph` (Charbonnier penalty ψ_ε,
photograph J_k in the renderer's units, μ_k its mean over the face's pixels
M_k) over one scalar field ``h`` on the model's mesh: the displacement of
each vertex along its normal, shared by all photographs (``N_k``, the welded
vertex normals of W_k, carry it into each pose and expression). The render
I_k is the face under the measurement's calibrated light with the fitted
BRDF and albedo map, its shading normals recomputed from the displaced
vertices as :meth:`mifaces.model.MorphableModel.vertex_normals` computes them
(area-weighted face normals, the rest of mifaces' convention).

Gradients come from Mitsuba's projective-sampling integrator
``direct_projective`` (Zhang et al., "Projective Sampling for Differentiable
Rendering of Geometry", SIGGRAPH Asia 2023): direct light, with the
derivatives of visibility (silhouettes, and with an area lamp cast shadows)
as well as of shading. Steps are Adam's in the latent variable of Mitsuba's
:class:`mi.ad.LargeSteps` (Nicolet et al., "Large Steps in Inverse Rendering
of Geometry", SIGGRAPH Asia 2021, eq. 10-11): ``u = (I + λL) d`` with L the
combinatorial Laplacian of the welded mesh (copies of a vertex split at a
texture seam share one row), so every step is smooth over the surface and
the copies move together. ``d`` is a 3-vector per vertex in the frame of the
first photograph; its component along that photograph's normals is ``h``
(the tangential part moves nothing: shading pins the depth along the normal,
a tangential slide only moves the texture, and is left out).

What pins what: shading pins h where the photographs see the face lit
(gradients of depth through the normals, i.e. of slopes: a constant offset
of a region shows only at its silhouette); λ ties neighbouring vertices, so
that h is smooth at the scale of a few edges; vertices that no photograph
sees keep h as LargeSteps' diffusion leaves it (near 0 far from seen ones).

The result is kept only if it lowers the loss on what the refinement did not
fit, rendered before and after with the same seed (common random numbers):
blocks of the face's pixels held out of E (a fixed random fraction,
:attr:`ShapeRefineSchedule.holdout`), and a whole photograph held out of E
(:attr:`ShapeRefineSchedule.judged`, :func:`judged_photographs`): a lamp (and,
where each photograph has its own, a pose) the refinement never saw, where
asked. Its loss must fall by at least :attr:`ShapeRefineSchedule.carry_over`
of the pixels' relative fall, the refined faces lit by the reflectance fitted
again on them (``refit``), as the pipeline goes on to use them. Held-out pixels alone do not catch the
refinement's usual failure: the displacement trades against the albedo and
the light the direct-light renders leave out, and the traded shape fits the
held-out pixels of the same photographs as well as the fitted ones; under a
lamp it did not see, it relights the face worse.
"""

from __future__ import annotations

import functools
import time
from dataclasses import asdict, dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from ..runtime.progress import progress as progress_bar
from ..render import FaceScene
from ..model.geometry import welded_normals
from .kernels import kernel_counts, kernel_history
from .photograph import LAMP_RADIUS_KEY, Appearance, RenderSettings, image_loss, mask_weight, photograph_view
from .schedule import holdout_pixels
from .shape_choice import chosen_iteration, judged_photographs, verdict
from .shape_schedule import RENDER_SIDE, ShapeRefineSchedule


@dataclass
class ShapeRefinement:
    """What :func:`refine_shape` returns.

    Attributes
    ----------
    shapes : dict
        Measurement name -> (V, 3) float32 world vertices (mm): the refined
        faces if ``accepted``, else the faces it started from.
    displacement : (V,) float32
        The refined displacement h along the normals (mm), whether accepted or not.
    accepted : bool
        Whether the held-out losses fell (:func:`refine_shape`: pixels and the judged photograph).
    reason : str
        Why the refined shape was kept or not.
    record : dict
        The schedule, the losses (fit and held-out, before and after), the
        loss per iteration, times and kernel launches.
    """

    shapes: dict[str, np.ndarray]
    displacement: np.ndarray
    accepted: bool
    reason: str
    record: dict = field(default_factory=dict)


def _mesh_normals(positions: mi.Point3f, triangles: tuple) -> mi.Vector3f:
    """Unit vertex normals of ``positions``: the area-weighted face normals
    summed at each vertex (:func:`mifaces.model.geometry.vertex_normals`), differentiable."""
    i0, i1, i2 = triangles
    flat = dr.ravel(positions)
    p0, p1, p2 = (dr.gather(mi.Point3f, flat, i) for i in (i0, i1, i2))
    face = dr.cross(p1 - p0, p2 - p0)
    n = dr.zeros(mi.Float, 3 * dr.width(positions))
    for i in (i0, i1, i2):
        dr.scatter_reduce(dr.ReduceOp.Add, n, face, i)
    return dr.normalize(dr.unravel(mi.Vector3f, n))


@dataclass(eq=False)
class _View:
    """One measurement: its view of the photograph, its start shape and normals, its held-out weight."""

    name: str
    view: object
    start: mi.Point3f
    normals: mi.Vector3f
    keys: dict
    fit_weight: mi.TensorXf
    heldout_weight: mi.TensorXf
    stop_weight: mi.TensorXf | None


class ShapeProblem:
    """The photographs as differentiable renders of the displaced faces.

    Parameters
    ----------
    capture : Capture
    shapes : mapping
        Measurement name -> (V, 3) world vertices (mm) of ``face_model``.
    face_model : MorphableModel
    estimate : BRDFEstimate
        The fitted BRDF: ``to_json()``, ``albedo.albedo``, ``normal_texture()``, ``specular_texture()``.
    schedule : ShapeRefineSchedule
    lamp_radius : float or None
    measurements : sequence of str, optional
    seed : int
        Chooses the held-out blocks.
    """

    def __init__(self, capture, shapes, face_model, estimate, schedule: ShapeRefineSchedule,
                 lamp_radius: float | None = None, measurements=None, seed: int = 0):
        names = [m.name for m in capture.measurements if m.name in shapes
                 and (measurements is None or m.name in measurements)]
        if not names:
            raise ValueError(f"no photograph to refine the shape on: none of the capture's measurements "
                             f"{[m.name for m in capture.measurements]} has a shape"
                             + ("" if measurements is None else f" among {list(measurements)}"))
        for name in names:
            if np.shape(shapes[name]) != (face_model.vertex_count, 3):
                raise ValueError(f"shape of measurement {name!r} has shape {np.shape(shapes[name])}, expected "
                                 f"({face_model.vertex_count}, 3) vertices of the face model")
            if not np.all(np.isfinite(shapes[name])):
                raise ValueError(f"shape of measurement {name!r} holds non-finite vertices")
        self.schedule, self.face_model = schedule, face_model
        self.shapes = {name: np.asarray(shapes[name], np.float32) for name in names}
        scale = capture.reflectance_scale() / np.pi
        appearance = Appearance.of(estimate)
        triangles = np.asarray(face_model.triangles, np.int64)
        self.triangles = tuple(mi.UInt32(np.ascontiguousarray(triangles[:, c], np.uint32)) for c in range(3))
        rng = np.random.default_rng([seed, 22])
        self.views, self.light_kinds = [], set()
        for m in capture.measurements:
            if m.name not in self.shapes:
                continue
            vertices = self.shapes[m.name]
            face = FaceScene(face_model, vertices)
            rendering = RenderSettings(schedule.factor(capture.camera_of(m)), schedule.spp, schedule.integrator(),
                                       sample_border=True)
            view = photograph_view(capture, m, face, appearance, face_model.region_map, scale, lamp_radius, rendering)
            self.light_kinds.add(view.light_kind)
            keys = {key: mi.UInt32(np.ascontiguousarray(part.index, np.uint32)) for key, part in face.meshes.items()}
            held = holdout_pixels(view.mask, schedule.holdout, schedule.holdout_block, rng)
            # half of the held-out blocks choose the iteration, the others judge the result
            stop = holdout_pixels(held, 0.5, schedule.holdout_block, rng) if schedule.early_stop else None
            normals = welded_normals(vertices, face_model.triangles)
            self.views.append(_View(m.name, view, mi.Point3f(np.ascontiguousarray(vertices.T)),
                                    mi.Vector3f(np.ascontiguousarray(normals.T, np.float32)), keys,
                                    mask_weight(view.mask & ~held),
                                    mask_weight(held if stop is None else held & ~stop),
                                    None if stop is None else mask_weight(stop)))
        self.direction = self.views[0].normals  # the frame of d: the first photograph's normals

    @functools.cached_property
    def steps(self):
        """Mitsuba's LargeSteps on the first photograph's face (built when first stepped: a problem
        only evaluated, as the judged photographs', does not factor it)."""
        try:
            return mi.ad.LargeSteps(mi.Float(np.ravel(next(iter(self.shapes.values())))),
                                    mi.UInt(np.ravel(self.face_model.triangles).astype(np.uint32)),
                                    float(self.schedule.smoothing))
        except ImportError as error:
            raise ImportError("refine_shape needs cholespy (pip install cholespy) for Mitsuba's LargeSteps") from error

    def latent_zero(self) -> mi.Float:
        """u of the zero displacement."""
        return dr.zeros(mi.Float, 3 * self.steps.n_verts)

    def height(self, u: mi.Float) -> mi.Float:
        """h (V,) of latent ``u``: d = (I + λL)⁻¹ u, its component along the first photograph's normals."""
        d = dr.unravel(mi.Vector3f, self.steps.from_differential(u))
        return dr.dot(d, self.direction)

    def set(self, view: _View, h: mi.Float) -> None:
        """Write the face displaced by ``h`` (and its normals) into ``view``'s scene."""
        positions = view.start + h * view.normals
        normals = _mesh_normals(positions, self.triangles)
        params = view.view.params
        positions, normals = dr.ravel(positions), dr.ravel(normals)
        for key, index in view.keys.items():
            params[f"{key}.vertex_positions"] = dr.ravel(dr.gather(mi.Point3f, positions, index))
            params[f"{key}.vertex_normals"] = dr.ravel(dr.gather(mi.Vector3f, normals, index))
        params.update()

    def loss(self, view: _View, h: mi.Float, seed: int, spp: int = 0) -> tuple[mi.Float, mi.Float | None]:
        """E_k of ``view`` displaced by ``h`` over its fitted pixels (``spp`` 0: the schedule's
        samples), and, read off the same render without gradients, over the blocks that choose the
        iteration (None without :attr:`ShapeRefineSchedule.early_stop`)."""
        self.set(view, h)
        image = mi.render(view.view.scene, view.view.params, spp=spp, seed=seed, seed_grad=seed + 1)
        image = image * view.view.scale
        stop = None
        if view.stop_weight is not None:
            stop = image_loss(dr.detach(image), view.view.target, view.stop_weight, self.schedule.epsilon)
            dr.schedule(stop)
        return image_loss(image, view.view.target, view.fit_weight, self.schedule.epsilon), stop

    def evaluate(self, h: mi.Float, seed: int) -> dict:
        """Mean E_k over the photographs on the fitted (``fit``), the held-out (``heldout``) and all
        (``all``) face pixels (no gradients)."""
        fit, held, every = [], [], []
        with dr.suspend_grad():
            h = mi.Float(dr.detach(h))
            for i, view in enumerate(self.views):
                self.set(view, h)
                image = mi.render(view.view.scene, spp=self.schedule.evaluation_spp, seed=seed + 2 * i)
                image = image * view.view.scale
                fit.append(image_loss(image, view.view.target, view.fit_weight, self.schedule.epsilon)[0])
                held.append(image_loss(image, view.view.target, view.heldout_weight, self.schedule.epsilon)[0])
                every.append(image_loss(image, view.view.target, mask_weight(view.view.mask),
                                        self.schedule.epsilon)[0])
        return {"fit": float(np.mean(fit)), "heldout": float(np.mean(held)), "all": float(np.mean(every))}

    def displaced(self, h: np.ndarray) -> dict[str, np.ndarray]:
        """Measurement -> (V, 3) float32 world vertices displaced by ``h`` along their welded normals."""
        return {name: displaced(v, h, self.face_model.triangles) for name, v in self.shapes.items()}


def displaced(vertices: np.ndarray, h: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``vertices`` (V, 3) moved by ``h`` (V,) mm along their welded normals, float32: a face as the
    refinement's displacement field moves it (the normals every photograph's view is displaced along)."""
    vertices = np.asarray(vertices, np.float32)
    return (vertices + np.asarray(h, np.float32)[:, None] * welded_normals(vertices, triangles)).astype(np.float32)


def refine_shape(capture, shapes, face_model, estimate, schedule: ShapeRefineSchedule | None = None, *,
                 lamp_radius: float | None = None, measurements=None, seed: int = 0, refit=None,
                 progress: bool = True) -> ShapeRefinement:
    """Refine fitted faces by a displacement along their normals, by
    differentiable rendering against the photographs (the module docstring's E).

    Parameters
    ----------
    capture : Capture
    shapes : mapping
        Measurement name -> (V, 3) world vertices (mm) of ``face_model``:
        :func:`mifaces.shape.shapes_in_world` or :func:`mifaces.shape.io.load_geometry`.
    face_model : MorphableModel
    estimate : BRDFEstimate
        The fitted BRDF and albedo map (:func:`mifaces.reflectance.estimate.fit_brdf`); where the
        schedule judges photographs (:func:`judged_photographs`), fitted without them: a fit that
        saw them would favour the shapes it was fitted on.
    schedule : ShapeRefineSchedule, optional
    lamp_radius : float, optional
        Radius (mm) of a spherical lamp in place of each point light; default
        the capture's ``metadata["lamp_radius_mm"]``, else point lights.
    measurements : sequence of str, optional
        The photographs to refine on (default: every one with a shape).
    seed : int
        Monte Carlo seeds and the held-out blocks derive from it.
    refit : callable, optional
        ``refit(shapes) -> BRDFEstimate``: the reflectance fitted again on the refined faces (of the
        fitted photographs only), to judge them as the rest of the pipeline would use them; None:
        ``estimate`` judges both (right where it does not depend on the shape, as a ground truth).
    progress : bool

    Returns
    -------
    ShapeRefinement
        The refined world vertices per measurement if the loss fell on held-out
        pixels and on the judged photographs (module docstring), else the shapes
        given; the displacement; the record.

    Examples
    --------
    >>> refined = refine_shape(capture, shapes, face_model, estimate)  # doctest: +SKIP
    >>> shapes = refined.shapes  # feeds capture_samples(capture, shapes, face_model, ...)  # doctest: +SKIP
    """
    schedule = schedule or ShapeRefineSchedule()
    if lamp_radius is None:
        lamp_radius = capture.metadata.get(LAMP_RADIUS_KEY)
    t0 = time.perf_counter()
    names = [m.name for m in capture.measurements if m.name in shapes
             and (measurements is None or m.name in measurements)]
    judged = judged_photographs(names, schedule.judged)
    problem = ShapeProblem(capture, shapes, face_model, estimate, schedule, lamp_radius,
                           [n for n in names if n not in judged] or None, seed)
    opt = mi.ad.Adam(lr=schedule.rate(0), uniform=True)  # UniformAdam, Nicolet et al. 2021 sec. 5
    opt["u"] = problem.latent_zero()
    t_build = time.perf_counter()
    evaluation_seed = seed * 7919 + (1 << 20)
    before = problem.evaluate(dr.zeros(mi.Float, face_model.vertex_count), evaluation_seed)
    t_before = time.perf_counter()
    history, latents = [], []  # latents: each iteration's u, of which the blocks that choose pick one
    bar = progress_bar(range(schedule.iterations), desc="refining shape", unit="it", enabled=progress)
    with kernel_history():
        for it in bar:
            t = time.perf_counter()
            total, chooser = 0.0, 0.0
            latents.append(dr.detach(opt["u"]))
            for i, view in enumerate(problem.views):
                loss, stop = problem.loss(view, problem.height(opt["u"]),
                                          seed=seed * 7919 + 2 * (it * len(problem.views) + i))
                dr.backward(loss)
                total += float(loss[0])
                chooser += float(stop[0]) if stop is not None else 0.0
            opt.step()
            opt.set_learning_rate(schedule.rate(it + 1))
            dr.eval(opt["u"])
            history.append([round(time.perf_counter() - t, 4), total / len(problem.views),
                            chooser / len(problem.views) if schedule.early_stop else None, *kernel_counts()])
            bar.set_postfix_str(f"loss {total / len(problem.views):.4g}")
    t_iterate = time.perf_counter()
    chosen = chosen_iteration([r[2] for r in history]) if schedule.early_stop else schedule.iterations
    with dr.suspend_grad():
        h = problem.height(mi.Float(latents[chosen] if schedule.early_stop else dr.detach(opt["u"])))
        dr.eval(h)
    after = problem.evaluate(h, evaluation_seed)
    h_np = np.asarray(h, np.float32)
    refined = problem.displaced(h_np)
    if judged:  # one displacement for all: the judged faces move with the others
        unmoved = dr.zeros(mi.Float, face_model.vertex_count)
        judge = ShapeProblem(capture, shapes, face_model, estimate, schedule, lamp_radius, judged, seed)
        before["judged"] = judge.evaluate(unmoved, evaluation_seed + 7)["all"]
        refined.update(judge.displaced(h_np))
        lit = refit({name: refined[name] for name in problem.shapes}) if refit else estimate
        judge = ShapeProblem(capture, refined, face_model, lit, schedule, lamp_radius, judged, seed)
        after["judged"] = judge.evaluate(unmoved, evaluation_seed + 7)["all"]
    accepted, reason = verdict(before, after, judged, schedule.carry_over)
    if schedule.early_stop and chosen == 0:  # no displacement: its losses differ from the start's by rounding
        accepted, reason = False, "the held-out blocks that choose the iteration chose the start: the model fit is kept"
    elif schedule.early_stop:
        reason += f" (iteration {chosen} of {schedule.iterations}, chosen by the other half of the held-out blocks)"
    t_end = time.perf_counter()
    record = {
        "method": "direct_projective + LargeSteps", "schedule": asdict(schedule),
        "downsample": schedule.factor(capture.camera),
        "lamp_radius_mm": float(lamp_radius) if lamp_radius else None, "lights": sorted(problem.light_kinds),
        "photographs": [v.name for v in problem.views], "judged_photographs": judged,
        "judged_refit": bool(judged and refit),
        "loss_before": before, "loss_after": after,
        "displacement_mm": {"max_abs": float(np.abs(h_np).max()), "rms": float(np.sqrt(np.mean(h_np ** 2)))},
        "chosen_iteration": chosen,
        "history_keys": ["seconds", "loss", "loss_choosing", "launches", "compiled", "compile_seconds"],
        "history": history,
        "seconds": {"build": t_build - t0, "loss_before": t_before - t_build, "iterations": t_iterate - t_before,
                    "per_iteration": (t_iterate - t_before) / schedule.iterations,
                    "per_iteration_after_first": float(np.mean([r[0] for r in history[1:]]))
                    if len(history) > 1 else None,
                    "loss_after": t_end - t_iterate, "total": t_end - t0},
    }
    shapes_out = refined if accepted else {name: np.asarray(shapes[name], np.float32) for name in refined}
    return ShapeRefinement(shapes_out, h_np, bool(accepted), reason, record)


__all__ = ["RENDER_SIDE", "ShapeRefineSchedule", "ShapeRefinement", "ShapeProblem", "displaced", "refine_shape"]
