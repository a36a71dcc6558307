"""Tests of mifaces.refine.shape: the displaced mesh's normals
against the numpy reference, seam copies moving together, the schedule's and
the inputs' checks, and the recovery of a cheek bump outside the model's span
from a small simulated capture."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import dataclasses
import types

import mitsuba as mi
import numpy as np
import pytest

from mifaces.capture import load_capture, read_ground_truth
from mifaces.model.geometry import vertex_normals, welded_normals
from mifaces.refine import shape_schedule
from mifaces.refine.shape import ShapeProblem, ShapeRefineSchedule, _mesh_normals, displaced, refine_shape
from mifaces.refine.shape_choice import chosen_iteration, judged_photographs, verdict
from mifaces.studio.detail import cheek_bump
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import simulate

#: The bump's height at its centre (mm) and width (standard deviation, mm).
BUMP_MM, BUMP_SIGMA_MM = 3.5, 8.0
#: Recovered peak within this fraction of the true peak.
PEAK_RTOL = 0.4
#: The mean vertex error over the bump (vertices above half its peak) falls at least by this factor.
ERROR_FALL = 0.5
#: Schedule of the recovery test: the defaults' but fewer iterations and no silhouette samples (the
#: test's time; the bump is inside the face, away from silhouettes), and the last photograph judged.
SCHEDULE = ShapeRefineSchedule(iterations=24, spp_silhouette=0, judged=1)


@dataclasses.dataclass
class _Albedo:
    albedo: np.ndarray


class TrueEstimate:
    """The ground truth's BRDF and albedo map where :func:`refine_shape` takes a
    fitted :class:`~mifaces.reflectance.estimate.BRDFEstimate`: the shape is
    then the only thing wrong."""

    def __init__(self, truth):
        self.truth, self.albedo = truth, _Albedo(truth.albedo)

    def to_json(self) -> dict:
        return self.truth.brdf

    def normal_texture(self):
        return None

    def specular_texture(self):
        return None


@pytest.fixture(scope="module")
def face_model():
    return mifaces.load_model()


@pytest.fixture(scope="module")
def bumped(tmp_path_factory, face_model):
    """A 4-photograph capture (128², 16 spp, seed 7: not the seed the defaults
    were chosen on; three poses under one lamp, fitted, and the front under a
    second lamp, judged) of a face with a cheek bump the model cannot express,
    and the true shapes without the bump."""
    bump = cheek_bump(face_model, face_model.shape_mean, BUMP_MM, BUMP_SIGMA_MM)
    model = dataclasses.replace(face_model, shape_mean=(face_model.shape_mean + bump).astype(np.float32))
    out = tmp_path_factory.mktemp("bump") / "capture"
    simulate(out, SimulationOptions(face_model=model, measurements=4, resolution=(128, 128), spp=16,
                                    albedo_resolution=256, seed=7), progress=False)
    capture = load_capture(out)
    truth = read_ground_truth(capture)
    flat = {t.name: (t.vertices - bump @ t.rotation.T).astype(np.float32) for t in truth.measurements}
    return capture, truth, bump, flat


def test_mesh_normals_match_numpy(face_model):
    rng = np.random.default_rng(1)
    v = face_model.shape_mean + rng.normal(0, 0.3, face_model.shape_mean.shape).astype(np.float32)
    tri = tuple(mi.UInt32(np.ascontiguousarray(face_model.triangles[:, c], np.uint32)) for c in range(3))
    got = np.asarray(_mesh_normals(mi.Point3f(np.ascontiguousarray(v.T)), tri)).T
    want = vertex_normals(v, face_model.triangles)
    used = np.linalg.norm(want, axis=1) > 0
    np.testing.assert_allclose(got[used], want[used], atol=2e-5)


def test_welded_normals_keep_seam_copies_together(face_model):
    v = face_model.shape_mean
    _, inverse, counts = np.unique(v, axis=0, return_inverse=True, return_counts=True)
    copies = counts[inverse.reshape(-1)] > 1
    assert copies.any(), "the model has no seam copies to test"
    moved = v + 2.0 * welded_normals(v, face_model.triangles)
    _, inverse_moved = np.unique(moved, axis=0, return_inverse=True)
    assert len(np.unique(inverse_moved)) == len(np.unique(inverse)), "seam copies came apart"
    # the unwelded normals would open the seams
    apart = v + 2.0 * vertex_normals(v, face_model.triangles)
    assert len(np.unique(apart, axis=0)) > len(np.unique(inverse))


@pytest.mark.parametrize("field, value", [("iterations", 0), ("spp", 0), ("learning_rate", 0.0),
                                          ("smoothing", -1.0), ("holdout", 1.0), ("spp_silhouette", -1),
                                          ("decay", 0.0), ("judged", -1), ("carry_over", 1.5)])
def test_schedule_rejects_bad_values(field, value):
    with pytest.raises(ValueError, match=f"ShapeRefineSchedule.{field}"):
        ShapeRefineSchedule(**{field: value})


def test_judged_photographs_are_the_last_and_leave_two_to_fit():
    names = ["m00", "m01", "m02", "m03"]
    assert judged_photographs(names, 1) == ["m03"]
    assert judged_photographs(names, 2) == ["m02", "m03"]
    assert judged_photographs(names, 3) == []  # one left to fit: none judged
    assert judged_photographs(names[:2], 1) == []
    assert judged_photographs(names, 0) == []


def test_verdict_needs_the_gain_to_carry_over_to_the_judged_photograph():
    before = {"fit": 1.0, "heldout": 1.0, "judged": 1.0}
    kept, reason = verdict(before, {"fit": 0.8, "heldout": 0.9, "judged": 0.95}, ["m05"], 0.5)
    assert kept and "held-out photograph m05 1 -> 0.95 (-5.0 %)" in reason and "kept" in reason
    # the held-out pixels fell by 10 %, the photograph no fit saw by 1 %: the model fit stays
    kept, reason = verdict(before, {"fit": 0.8, "heldout": 0.9, "judged": 0.99}, ["m05"], 0.5)
    assert not kept and "did not carry over to the held-out photograph m05" in reason
    kept, _ = verdict(before, {"fit": 0.8, "heldout": 0.9, "judged": 0.99}, ["m05"], 0.1)
    assert kept
    kept, reason = verdict(before, {"fit": 0.8, "heldout": 1.1, "judged": 0.9}, ["m05"], 0.5)
    assert not kept and "did not fall, the model fit is kept" in reason
    # no photograph to judge on: the pixels decide
    kept, _ = verdict(dict(before, judged=None), {"fit": 0.8, "heldout": 0.9, "judged": None}, [], 0.5)
    assert kept


def test_refine_lit_keeps_the_judged_photograph_out_of_its_fits(monkeypatch):
    """The quick fit that lights the refinement, and the refit that judges it, never see the judged
    photograph (a fit that saw it would favour the faces it was made on); without one judged, the
    samples given light the faces."""
    import mifaces.refine.shape_lit as module

    names = ["m00", "m01", "m02", "m03"]
    capture = types.SimpleNamespace(measurements=[types.SimpleNamespace(name=n) for n in names])
    shapes = {n: np.zeros((3, 3), np.float32) for n in names}
    seen = []
    monkeypatch.setattr(module, "capture_samples",
                        lambda capture, faces, *a, **k: seen.append(("samples", sorted(faces))) or "samples")
    monkeypatch.setattr(module, "fit_brdf", lambda capture, brdf, faces, samples=None, **k:
                        seen.append(("fit", sorted(faces), samples)) or "estimate")

    def refine(capture, faces, face_model, estimate, schedule, refit=None, progress=True):
        seen.append(("refine", sorted(faces), estimate))
        refit({n: faces[n] for n in names[:3]})  # refine_shape refits on the refined fitted faces
        return "result"

    monkeypatch.setattr(module, "refine_shape", refine)
    judged = ShapeRefineSchedule(judged=1)
    assert module.refine_lit(capture, shapes, None, "given", schedule=judged, progress=False) == "result"
    assert seen == [("samples", names[:3]), ("fit", names[:3], "samples"), ("refine", names, "estimate"),
                    ("samples", names[:3]), ("fit", names[:3], "samples")]
    seen.clear()
    module.refine_lit(capture, shapes, None, "given", progress=False)  # the default: none judged
    assert seen[:2] == [("fit", names, "given"), ("refine", names, "estimate")]


def test_render_downsample_brings_the_longer_side_to_render_side():
    camera = types.SimpleNamespace(width=512, height=512)
    assert shape_schedule.RENDER_SIDE == 256
    assert ShapeRefineSchedule().factor(camera) == 2
    assert ShapeRefineSchedule().factor(types.SimpleNamespace(width=192, height=168)) == 1  # Yale: as it is
    assert ShapeRefineSchedule().factor(types.SimpleNamespace(width=4000, height=3000)) == 16  # 250 x 187
    assert ShapeRefineSchedule().factor(types.SimpleNamespace(width=257, height=100)) == 2
    assert ShapeRefineSchedule(downsample=1).factor(camera) == 1  # asked for: full resolution
    with pytest.raises(ValueError, match="ShapeRefineSchedule.downsample"):
        ShapeRefineSchedule(downsample=0)


def test_renders_are_downsampled_by_default(bumped, face_model, monkeypatch):
    capture, truth, _, flat = bumped
    full = ShapeProblem(capture, flat, face_model, TrueEstimate(truth), ShapeRefineSchedule())
    monkeypatch.setattr(shape_schedule, "RENDER_SIDE", 64)  # the 128² capture then renders at 64²
    half = ShapeProblem(capture, flat, face_model, TrueEstimate(truth), ShapeRefineSchedule())
    for a, b in zip(full.views, half.views):
        film = b.view.scene.sensors()[0].film()
        assert tuple(film.size()) == (64, 64)
        assert tuple(film.crop_size()) == b.view.mask.shape[::-1]
        assert b.view.mask.shape[0] <= (a.view.mask.shape[0] + 1) // 2
        assert b.view.mask.shape[1] <= (a.view.mask.shape[1] + 1) // 2
        assert tuple(a.view.scene.sensors()[0].film().size()) == (128, 128)


def test_bad_shapes_are_named(bumped, face_model):
    capture, truth, _, flat = bumped
    name = capture.measurements[0].name
    with pytest.raises(ValueError, match=f"{name}.*expected"):
        refine_shape(capture, {name: flat[name][:100]}, face_model, TrueEstimate(truth), progress=False)
    with pytest.raises(ValueError, match="no photograph"):
        refine_shape(capture, {"nobody": flat[name]}, face_model, TrueEstimate(truth), progress=False)


@pytest.mark.slow
def test_recovers_cheek_bump(bumped, face_model):
    capture, truth, bump, flat = bumped
    result = refine_shape(capture, flat, face_model, TrueEstimate(truth), SCHEDULE, seed=1, progress=False)
    height = np.linalg.norm(bump, axis=1)
    peak = int(np.argmax(height))
    assert abs(result.displacement[peak] - BUMP_MM) < PEAK_RTOL * BUMP_MM, result.displacement[peak]
    region = height > 0.5 * BUMP_MM
    moved = {name: displaced(v, result.displacement, face_model.triangles) for name, v in flat.items()}
    for t in truth.measurements:  # the judged photograph's face too: one displacement for all
        before = np.linalg.norm(flat[t.name] - t.vertices, axis=1)[region].mean()
        after = np.linalg.norm(moved[t.name] - t.vertices, axis=1)[region].mean()
        assert after < ERROR_FALL * before, (t.name, before, after)
    record = result.record
    assert record["loss_after"]["fit"] < record["loss_before"]["fit"]
    assert record["loss_after"]["heldout"] < record["loss_before"]["heldout"]
    # the last photograph judged, unfitted; the verdict is the rule's on the recorded losses
    assert record["judged_photographs"] == [capture.measurements[-1].name]
    assert capture.measurements[-1].name not in record["photographs"]
    judged_fall = 1 - record["loss_after"]["judged"] / record["loss_before"]["judged"]
    pixels_fall = 1 - record["loss_after"]["heldout"] / record["loss_before"]["heldout"]
    assert result.accepted == (judged_fall >= SCHEDULE.carry_over * pixels_fall), (result.reason, judged_fall)
    for name, v in (moved if result.accepted else flat).items():
        np.testing.assert_allclose(result.shapes[name], v, atol=1e-3)
    assert len(record["history"]) == SCHEDULE.iterations
    compiled = record["history_keys"].index("compiled")
    assert sum(h[compiled] for h in record["history"][2:]) == 0, "kernels recompiled after the first iterations"


@pytest.mark.slow
def test_keeps_model_fit_when_held_out_loss_rises(bumped, face_model):
    capture, truth, _, _ = bumped
    true = {t.name: t.vertices for t in truth.measurements}
    # steps far too large from the true shape: the held-out loss can only rise
    schedule = ShapeRefineSchedule(iterations=3, learning_rate=200.0, evaluation_spp=8, early_stop=False)  # 50x
    result = refine_shape(capture, true, face_model, TrueEstimate(truth), schedule, seed=1, progress=False)
    assert not result.accepted
    assert "did not fall" in result.reason
    for name, v in true.items():
        np.testing.assert_array_equal(result.shapes[name], v)
    assert np.abs(result.displacement).max() > 1.0
    # choosing the iteration by the held-out blocks, the start (no displacement) is chosen
    chosen = refine_shape(capture, true, face_model, TrueEstimate(truth),
                          dataclasses.replace(schedule, early_stop=True), seed=1, progress=False)
    assert chosen.record["chosen_iteration"] == 0
    assert np.abs(chosen.displacement).max() < 1e-5
    assert not chosen.accepted and "chose the start" in chosen.reason
    for name, v in true.items():
        np.testing.assert_array_equal(chosen.shapes[name], v)


def test_chosen_iteration_averages_out_one_lucky_iteration():
    losses = [5.0, 4.0, 3.0, 2.5, 2.6, 3.0, 3.5, 4.0, 4.5, 1.0]  # the last: one render's luck
    assert chosen_iteration(losses) == 4  # averaged over 5: (3.0 + 2.5 + 2.6 + 3.0 + 3.5) / 5 the lowest
    assert chosen_iteration(losses, window=1) == 9
    assert chosen_iteration([2.0, 1.0, 1.0], window=1) == 1  # the earliest of equals
    with pytest.raises(ValueError, match="one loss per iteration"):
        chosen_iteration([])
