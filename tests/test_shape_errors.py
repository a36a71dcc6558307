"""mifaces.validation.shape_errors: the world-frame errors of a fitted face, on faces moved by hand."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import mifaces
from mifaces.model.geometry import rotation_matrix
from mifaces.validation.shape_errors import shape_errors

#: A camera 1200 mm in front of the face, looking along -z of the world (its +z row is world -z).
CAMERA = SimpleNamespace(position=np.array([0.0, 0.0, 1200.0]), rotation=np.diag([1.0, -1.0, -1.0]))


@pytest.fixture(scope="module")
def face_model():
    return mifaces.load_model()


def _face(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, [60.0, 80.0, 40.0], (n, 3))


def test_a_face_scaled_about_the_camera_is_the_scale_depth_ambiguity():
    """The true face made 0.3 % larger about the camera's centre (every pixel the same): the world
    error is about 0.3 % of the distance, all of it in depth and in the scale, none left after it."""
    true = _face()
    fitted = CAMERA.position + 1.003 * (true - CAMERA.position)
    e = shape_errors(fitted, true, np.ones(len(true), bool), CAMERA)
    assert e["scale_pct"] == pytest.approx(0.3, abs=1e-9) and e["scaled_mm"] < 1e-9
    assert e["depth_mm"] == pytest.approx(0.003 * 1200.0, rel=0.01)  # farther from the camera: positive
    assert e["world_mm"] == pytest.approx(3.6, rel=0.1) and e["aligned_mm"] > 0.05  # a scale is no rigid motion


def test_a_turned_and_shifted_face_is_a_rigid_error():
    """A rigid motion of the true face, 3 mm of it towards the camera: aligned away, seen in the
    world error; the size is right, so no scale explains it."""
    true = _face(seed=1)
    rotation = rotation_matrix(2.0, -1.0, 0.5)
    fitted = true @ rotation.T + np.array([1.0, -2.0, 3.0])
    e = shape_errors(fitted, true, np.ones(len(true), bool), CAMERA)
    assert e["aligned_mm"] < 1e-9 and e["world_mm"] > 3.0
    assert e["depth_mm"] == pytest.approx(-3.0, abs=0.5)  # +3 mm along world z: towards the camera
    assert abs(e["scale_pct"]) < 1e-9 and e["scaled_mm"] == pytest.approx(e["world_mm"])
    # only the vertices the mask selects count
    mask = np.zeros(len(true), bool)
    mask[:10] = True
    assert shape_errors(fitted, true, mask, CAMERA)["vertices"] == 10


def test_normals_error_sees_a_turn_and_a_bend_but_not_a_shift(face_model):
    """``normal_deg``: 0 for the true face moved along its depth, the turn's angle for a turned face,
    and above 0 for a face bent by a bump that moves no vertex by more than 1.5 mm."""
    true = face_model.shape_mean.astype(np.float64)
    mask, triangles = np.ones(len(true), bool), face_model.triangles
    shifted = shape_errors(true + np.array([0.0, 0.0, 5.0]), true, mask, CAMERA, triangles)
    assert shifted["world_mm"] == pytest.approx(5.0) and shifted["normal_deg"] < 0.01
    turned = shape_errors(true @ rotation_matrix(0.0, 4.0, 0.0).T, true, mask, CAMERA, triangles)
    assert 2.0 < turned["normal_deg"] <= 4.0 + 1e-3  # a normal turns by 4 degrees at most (along the axis: 0)
    centre = true[np.argmax(true[:, 2])]  # the tip of the nose
    bump = 1.5 * np.exp(-np.sum((true - centre) ** 2, axis=1) / (2 * 6.0 ** 2))
    area = bump > 0.1  # over the bump: its slopes reach 0.15 (8.5 degrees)
    bent = shape_errors(true + bump[:, None] * face_model.vertex_normals(true), true, area, CAMERA, triangles)
    assert bent["world_mm"] < 1.0 and bent["normal_deg"] > 2.0
    assert "normal_deg" not in shape_errors(true, true, mask, CAMERA)  # no triangles, no normals


def test_floor_depth_separates_the_depth_from_the_shape():
    """validation/floor_depth.py's faces: a fitted face turned 2 degrees and moved 4 mm away from the
    camera and 1 mm aside. Removing its depth offset leaves no depth and its own shape error; the
    rigid alignment leaves nothing; the true face moved by the fitted depth has that depth and no
    shape error; the 1 mm face is 1 mm deeper."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "validation"))
    from floor_depth import VARIANTS, variants

    true = _face()
    mask = np.ones(len(true), bool)
    forward = CAMERA.rotation[2]
    fitted = (true - true.mean(axis=0)) @ rotation_matrix(0.0, 2.0, 0.0).T + true.mean(axis=0)
    fitted = fitted + 4.0 * forward + np.array([1.0, 0.0, 0.0])
    faces = variants(fitted, true, mask, CAMERA)
    assert tuple(faces) == VARIANTS
    errors = {key: shape_errors(v, true, mask, CAMERA) for key, v in faces.items()}
    assert errors["fitted"]["depth_mm"] == pytest.approx(4.0, abs=1e-6)
    assert abs(errors["depth_removed"]["depth_mm"]) < 1e-9
    assert errors["depth_removed"]["aligned_mm"] == pytest.approx(errors["fitted"]["aligned_mm"], abs=1e-6)
    assert errors["depth_removed"]["world_mm"] < errors["fitted"]["world_mm"] - 1.0
    assert errors["aligned"]["world_mm"] < 1e-6
    assert errors["truth_at_fitted_depth"]["aligned_mm"] < 1e-6
    assert errors["truth_at_fitted_depth"]["depth_mm"] == pytest.approx(4.0, abs=1e-6)
    assert errors["truth_1mm_deeper"]["depth_mm"] == pytest.approx(1.0, abs=1e-9)
    assert errors["truth_1mm_deeper"]["world_mm"] == pytest.approx(1.0, abs=1e-9)
