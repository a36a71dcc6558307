"""Tests of mifaces.refine.shape: the displaced mesh's normals
against the numpy reference, seam copies moving together, the schedule's and
the inputs' checks, and the recovery of a cheek bump outside the model's span
from a small simulated capture."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import dataclasses

import mitsuba as mi
import numpy as np
import pytest

from mifaces.capture import load_capture, read_ground_truth
from mifaces.model.geometry import vertex_normals, welded_normals
from mifaces.refine.shape import ShapeRefineSchedule, _mesh_normals, refine_shape
from mifaces.studio.detail import cheek_bump
from mifaces.studio.simulate import simulate

#: The bump's height at its centre (mm) and width (standard deviation, mm).
BUMP_MM, BUMP_SIGMA_MM = 3.5, 8.0
#: Recovered peak within this fraction of the true peak.
PEAK_RTOL = 0.4
#: The mean vertex error over the bump (vertices above half its peak) falls at least by this factor.
ERROR_FALL = 0.5
#: Schedule of the recovery test: the defaults' but fewer iterations and no silhouette samples (the
#: test's time; the bump is inside the face, away from silhouettes).
SCHEDULE = ShapeRefineSchedule(iterations=24, spp_silhouette=0)


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
    """A 3-photograph capture (128², 16 spp, seed 7: not the seed the defaults
    were chosen on) of a face with a cheek bump the model cannot express, and
    the true shapes without the bump."""
    bump = cheek_bump(face_model, face_model.shape_mean, BUMP_MM, BUMP_SIGMA_MM)
    model = dataclasses.replace(face_model, shape_mean=(face_model.shape_mean + bump).astype(np.float32))
    out = tmp_path_factory.mktemp("bump") / "capture"
    simulate(out, model=model, measurements=3, resolution=(128, 128), spp=16, albedo_resolution=256, seed=7,
             progress=False)
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
                                          ("decay", 0.0)])
def test_schedule_rejects_bad_values(field, value):
    with pytest.raises(ValueError, match=f"ShapeRefineSchedule.{field}"):
        ShapeRefineSchedule(**{field: value})


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
    for t in truth.measurements:
        before = np.linalg.norm(flat[t.name] - t.vertices, axis=1)[region].mean()
        after = np.linalg.norm(result.shapes[t.name] - t.vertices, axis=1)[region].mean()
        assert after < ERROR_FALL * before, (t.name, before, after)
    record = result.record
    assert result.accepted, result.reason
    assert record["loss_after"]["fit"] < record["loss_before"]["fit"]
    assert record["loss_after"]["heldout"] < record["loss_before"]["heldout"]
    assert len(record["history"]) == SCHEDULE.iterations
    assert sum(h[3] for h in record["history"][2:]) == 0, "kernels recompiled after the first iterations"


@pytest.mark.slow
def test_keeps_model_fit_when_held_out_loss_rises(bumped, face_model):
    capture, truth, _, _ = bumped
    true = {t.name: t.vertices for t in truth.measurements}
    # steps far too large from the true shape: the held-out loss can only rise
    schedule = ShapeRefineSchedule(iterations=2, learning_rate=200.0, evaluation_spp=8)  # 50x the default
    result = refine_shape(capture, true, face_model, TrueEstimate(truth), schedule, seed=1, progress=False)
    assert not result.accepted
    assert "did not fall" in result.reason
    for name, v in true.items():
        np.testing.assert_array_equal(result.shapes[name], v)
    assert np.abs(result.displacement).max() > 1.0
