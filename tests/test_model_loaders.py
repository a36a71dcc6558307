"""Tests of the model readers: small synthetic files in the exact Basel/SFM layouts, and malformed ones."""

from __future__ import annotations

import sys

import mifaces  # noqa: F401  # isort: skip

import h5py
import numpy as np
import pytest
import scipy.io

from mifaces.model import ModelFormatError, load_model
from mifaces.model.geometry import grid_triangles
from mifaces.model.regions import REGIONS
from mifaces.model.texture_space import rasterize

from test_model import SFM_DIR, SFM_NPZ, needs_sfm

ROWS, COLS = 9, 11


def _toy_face(k: int = 4, seed: int = 0):
    """A patch of a cylinder (radius 80 mm) looking along +z, with an orthonormal basis."""
    h = np.linspace(60, -60, ROWS)
    phi = np.linspace(-1.0, 1.0, COLS)
    hh, pp = np.meshgrid(h, phi, indexing="ij")
    mean = np.stack([80 * np.sin(pp), hh, 80 * np.cos(pp)], -1).reshape(-1, 3)
    n3 = mean.size
    q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((n3, k)))
    var = np.array([30.0, 20.0, 10.0, 5.0][:k])
    tri = grid_triangles(ROWS, COLS)  # counter-clockwise from outside
    return mean, q, var, tri


def _write_bfm2009(path, k=4, **overrides):
    mean, q, var, tri = _toy_face(k)
    data = {
        "shapeMU": (mean.reshape(-1, 1) * 1000.0).astype(np.float32),  # micrometres
        "shapePC": q.astype(np.float32),
        "shapeEV": np.sqrt(var).reshape(-1, 1).astype(np.float32) * 1000.0,  # standard deviations, um
        "texMU": np.full((mean.size, 1), 128.0, np.float32),
        "texPC": q[:, :3].astype(np.float32),
        "texEV": np.array([[20.0], [10.0], [5.0]], np.float32),
        "tl": (tri[:, [0, 2, 1]] + 1).astype(np.float64),  # 1-based, BFM's clockwise winding
    }
    data.update(overrides)
    data = {key: value for key, value in data.items() if value is not None}
    scipy.io.savemat(path, data)
    return mean, q, var, tri


def _write_bfm2017(path, drop=None, replace=None):
    mean, q, var, tri = _toy_face(4)
    items = {
        "shape/model/mean": mean.ravel().astype(np.float32),
        "shape/model/pcaBasis": q.astype(np.float32),
        "shape/model/pcaVariance": var.astype(np.float32),
        "shape/representer/points": mean.T.astype(np.float32),
        "shape/representer/cells": tri.T.astype(np.uint32),
        "color/model/mean": np.full(mean.size, 0.5, np.float32),
        "color/model/pcaBasis": q[:, :2].astype(np.float32),
        "color/model/pcaVariance": np.array([0.01, 0.005], np.float32),
        "expression/model/mean": np.zeros(mean.size, np.float32),
        "expression/model/pcaBasis": q[:, 2:].astype(np.float32),
        "expression/model/pcaVariance": np.array([4.0, 1.0], np.float32),
    }
    items.update(replace or {})
    with h5py.File(path, "w") as f:
        for key, value in items.items():
            if key != drop:
                f[key] = value
    return mean, q, var, tri


def test_basel2009(tmp_path):
    path = tmp_path / "01_MorphableModel.mat"
    mean, q, var, tri = _write_bfm2009(path)
    model = load_model(path)
    np.testing.assert_allclose(model.shape_mean, mean, atol=1e-3)  # millimetres
    np.testing.assert_allclose(model.shape_variance, var, rtol=1e-5)  # squared standard deviations
    np.testing.assert_allclose(model.color_mean, 128 / 255, atol=1e-6)
    np.testing.assert_allclose(model.color_variance, (np.array([20.0, 10, 5]) / 255) ** 2, rtol=1e-5)
    np.testing.assert_array_equal(model.triangles, tri)  # 0-based, re-oriented outwards
    assert model.metadata["format"] == "basel2009-mat"
    # Cylindrical uv: u grows with x, v with decreasing height, injective.
    assert np.all(np.diff(model.uv.reshape(ROWS, COLS, 2)[:, :, 0], axis=1) > 0)
    assert np.all(np.diff(model.uv.reshape(ROWS, COLS, 2)[:, :, 1], axis=0) > 0)
    assert rasterize(model.uv, model.triangles, (64, 64)).count.max() == 1
    assert model.regions == ["skin"]


@pytest.mark.parametrize("key, value, message", [
    ("shapePC", None, "missing key 'shapePC'"),
    ("tl", None, "missing key 'tl'"),
    ("shapeEV", np.ones((3, 1), np.float32), r"'shapeEV' has shape \(3, 1\), expected \(4, 1\)"),
    ("shapePC", np.ones((10, 4), np.float32), r"'shapePC' has shape \(10, 4\), expected \(297, \*\)"),
    ("tl", np.ones((5, 4)), r"'tl' has shape \(5, 4\), expected \(\*, 3\)"),
])
def test_basel2009_malformed(tmp_path, key, value, message):
    path = tmp_path / "bad.mat"
    _write_bfm2009(path, **{key: value})
    with pytest.raises(ModelFormatError, match=message) as info:
        load_model(path)
    assert "bad.mat" in str(info.value)


def test_basel2017(tmp_path):
    path = tmp_path / "model2017-1_face12_nomouth.h5"
    mean, q, var, tri = _write_bfm2017(path)
    model = load_model(path, landmarks={31: 49, 9: 93})
    np.testing.assert_allclose(model.shape_mean, mean, atol=1e-4)
    np.testing.assert_allclose(model.shape_basis, q, atol=1e-6)
    np.testing.assert_allclose(model.shape_variance, var)
    np.testing.assert_array_equal(model.triangles, tri)
    assert model.color_dim == 2 and model.expression_dim == 2
    d = np.array([1.0, 0.0])
    np.testing.assert_allclose((model.shape(None, d) - model.shape()).ravel(), 2.0 * q[:, 2], atol=1e-4)
    assert model.ibug_landmarks == {9: 93, 31: 49}
    # Normals of a cylinder patch point away from its axis.
    n = model.vertex_normals()
    radial = mean * np.array([1, 0, 1]) / 80.0
    assert np.all(np.sum(n * radial, axis=1) > 0.99)


@pytest.mark.parametrize("drop, replace, message", [
    ("shape/model/pcaBasis", None, "missing key 'shape/model/pcaBasis'"),
    ("shape/representer/cells", None, "missing key 'shape/representer/cells'"),
    ("color/model/pcaVariance", None, "missing key 'color/model/pcaVariance'"),
    (None, {"shape/model/pcaVariance": np.ones(3, np.float32)},
     r"'shape/model/pcaVariance' has shape \(3,\), expected \(4,\)"),
    (None, {"shape/representer/cells": np.zeros((4, 10), np.uint32)},
     r"'shape/representer/cells' has shape \(4, 10\), expected \(3, \*\)"),
    (None, {"expression/model/pcaBasis": np.zeros((12, 2), np.float32)},
     r"'expression/model/pcaBasis' has shape \(12, 2\), expected \(297, \*\)"),
])
def test_basel2017_malformed(tmp_path, drop, replace, message):
    path = tmp_path / "bad.h5"
    _write_bfm2017(path, drop=drop, replace=replace)
    with pytest.raises(ModelFormatError, match=message):
        load_model(path)


def test_not_hdf5(tmp_path):
    path = tmp_path / "junk.h5"
    path.write_bytes(b"not hdf5")
    with pytest.raises(ModelFormatError, match="junk.h5"):
        load_model(path)


@needs_sfm
@pytest.mark.parametrize("key, shape, message", [
    ("shape_basis", None, "missing key 'shape_basis'"),
    ("uv", None, "missing key 'uv'"),
    ("shape_eigenvalues", (62,), r"'shape_eigenvalues' has shape \(62,\), expected \(63,\)"),
    ("uv", (3448, 3), r"'uv' has shape \(3448, 3\), expected \(3448, 2\)"),
])
def test_sfm_malformed(tmp_path, key, shape, message):
    with np.load(SFM_NPZ) as data:
        arrays = dict(data)
    if shape is None:
        del arrays[key]
    else:
        arrays[key] = np.ones(shape, arrays[key].dtype)
    path = tmp_path / "sfm_bad.npz"
    np.savez(path, **arrays)
    if key == "shape_basis" and shape is None:
        # Without its basis the file is not recognised as an SFM npz at all.
        with pytest.raises(ModelFormatError, match="neither a mifaces model nor|shape_basis"):
            load_model(path)
        from mifaces.model.sfm import load_sfm_npz

        with pytest.raises(ModelFormatError, match=message):
            load_sfm_npz(path)
    else:
        with pytest.raises(ModelFormatError, match=message):
            load_model(path)


@needs_sfm
def test_eos_binary_matches_npz():
    pytest.importorskip("eos", reason="eos-py (optional extra 'eos') not installed")
    a = load_model(SFM_DIR / "sfm_shape_3448.bin")
    b = load_model(SFM_NPZ)
    np.testing.assert_allclose(a.shape_mean, b.shape_mean, atol=1e-5)
    np.testing.assert_allclose(a.shape_basis, b.shape_basis, atol=1e-6)
    np.testing.assert_array_equal(a.triangles, b.triangles)
    np.testing.assert_array_equal(a.landmarks, b.landmarks)
    np.testing.assert_array_equal(a.region_map, b.region_map)
    assert a.expression_names == b.expression_names
    assert set(a.regions) == {"skin", "lips", "eyes", "eyebrows", "nostrils"}
    assert np.all(a.region_map[a.region_map > 0] >= REGIONS["skin"])


@needs_sfm
def test_eos_missing_names_the_package(monkeypatch):
    monkeypatch.setitem(sys.modules, "eos", None)  # makes `import eos` fail
    with pytest.raises(ImportError, match="eos-py"):
        load_model(SFM_DIR / "sfm_shape_3448.bin")
