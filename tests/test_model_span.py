"""validation/model_span.py's surface measure: distances to a mesh's surface, and the surface fit, on cases
whose answer is known without the code under test."""

from __future__ import annotations

import importlib

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip
import numpy as np
import pytest
import trimesh.creation

from mifaces.model.geometry import grid_triangles


@pytest.fixture(scope="module")
def span(request):
    monkeypatch = pytest.MonkeyPatch()
    monkeypatch.syspath_prepend(str(request.config.rootpath / "validation"))
    yield importlib.import_module("model_span")
    monkeypatch.undo()


def _grid(rows=11, cols=21, step=2.0):
    """A flat grid in the plane z = 0, x in [0, 40], y in [0, 20] (mm)."""
    y, x = np.meshgrid(np.arange(rows) * step, np.arange(cols) * step, indexing="ij")
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1), grid_triangles(rows, cols)


def test_points_above_a_plane_are_their_height_away_and_points_beyond_it_the_distance_to_its_edge(span):
    vertices, triangles = _grid()
    rng = np.random.default_rng(0)
    inside = np.stack([rng.uniform(0, 40, 500), rng.uniform(0, 20, 500), rng.uniform(-5, 5, 500)], axis=1)
    np.testing.assert_allclose(span.surface_distance(inside, vertices, triangles), np.abs(inside[:, 2]), atol=1e-9)
    # beyond the edge x = 40 and above: the distance to the edge (x, z) = (40, 0); beyond a corner, to the corner
    beyond = np.array([[43.0, 10.0, 4.0], [40.5, 3.3, 0.0], [43.0, 23.0, 0.0], [-3.0, -4.0, 12.0]])
    expected = [5.0, 0.5, np.sqrt(18.0), 13.0]
    np.testing.assert_allclose(span.surface_distance(beyond, vertices, triangles), expected, atol=1e-9)
    surface = span.Surface(vertices, triangles)
    np.testing.assert_allclose(surface.border_distance(np.array([[12.0, 9.0, 0.0], [41.0, 5.0, 0.0]])), [9.0, 1.0])


def test_a_surface_is_zero_from_itself_and_its_offset_along_its_normals(span):
    """An icosphere of radius 50 mm: points on its triangles are on it; its vertices pushed out along the radius
    by d are d from it (a convex polyhedron's vertex is the closest point along its own radius)."""
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=50.0)
    vertices, triangles = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    rng = np.random.default_rng(1)
    w = rng.dirichlet(np.ones(3), size=len(triangles))
    on = np.einsum("tb,tbc->tc", w, vertices[triangles])
    assert np.abs(span.surface_distance(on, vertices, triangles)).max() < 1e-9
    for offset in (0.3, 2.0, 7.5):
        pushed = vertices * (1.0 + offset / 50.0)
        np.testing.assert_allclose(span.surface_distance(pushed, vertices, triangles), offset, rtol=1e-9)
    # a surface shifted along its normal by 1.7 mm: its own points (off the border) are 1.7 mm from it
    vertices_plane, triangles_plane = _grid()
    shifted = vertices_plane + [0.0, 0.0, 1.7]
    inner = vertices_plane[(vertices_plane[:, 0] > 0) & (vertices_plane[:, 1] > 0)]
    np.testing.assert_allclose(span.surface_distance(inner, shifted, triangles_plane), 1.7, rtol=1e-12)


def test_the_surface_fit_finds_a_face_of_the_model_itself(span):
    """The built-in face with 10 known modes, moved by a known rotation and translation, as the target: from the
    mean face at a wrong pose, the surface fit lands on it (distance and coefficients)."""
    model = mifaces.load_model()
    face = np.flatnonzero(np.isin(model.vertex_regions(), [1]) & (model.uv[:, 0] < 0.8) & (model.uv[:, 1] < 0.8))
    region = face[::4]
    truth = np.array([1.2, -0.8, 0.5, 0.9, -1.1, 0.3, -0.4, 0.7, 0.2, -0.6])
    angle = np.radians(4.0)
    turn = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    target = model.shape(np.concatenate([truth, np.zeros(model.shape_dim - 10)])).astype(np.float64)
    target = target @ turn.T + [3.0, -2.0, 5.0]
    keep = np.isin(model.triangles, face).all(axis=1)
    surface = span.Surface(target, model.triangles[keep])
    mean, basis = model.shape_mean[region].astype(np.float64), span.scaled_basis(model, region, 10)
    a, rotation, translation, distance, _ = span.fit_surface(
        mean, basis, np.ones(len(region)), surface, np.zeros(10), np.eye(3), np.zeros(3), prior_weight=1e-6,
        rounds=12)
    assert distance.mean() < 0.01
    np.testing.assert_allclose(a, truth, atol=0.02)
    np.testing.assert_allclose(rotation, turn, atol=1e-3)
