"""mifaces.shape_errors: the world-frame errors of a fitted face, on faces moved by hand."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from mifaces.model.geometry import rotation_matrix
from mifaces.shape_errors import shape_errors

#: A camera 1200 mm in front of the face, looking along -z of the world (its +z row is world -z).
CAMERA = SimpleNamespace(position=np.array([0.0, 0.0, 1200.0]), rotation=np.diag([1.0, -1.0, -1.0]))


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
