"""The pixels a face covers (mifaces.render.face_pixels): the pixel centres' rays with their region
labels, the filtered footprint of a render, and the front of the face."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import numpy as np
import pytest

from mifaces.render.face_pixels import face_pixels, front_of_face_pixels, texture_coordinates, texture_lookup
from mifaces.model import load_model
from mifaces.model.regions import REGIONS
from mifaces.render import FaceScene

from conftest import front_camera


@pytest.fixture(scope="module")
def face():
    mifaces.set_variant("llvm_ad_rgb")
    model = load_model()
    return model, FaceScene(model, model.shape_mean)


def test_centre_rays_label_the_face_pixels_by_region(face):
    model, scene = face
    labels = face_pixels(scene, front_camera(150.0), spp=None, region_map=model.region_map)
    mask = face_pixels(scene, front_camera(150.0), spp=None)
    assert labels.shape == mask.shape == (64, 48) and mask.dtype == bool
    np.testing.assert_array_equal(labels > 0, mask)
    assert 0.2 < mask.mean() < 0.9
    assert set(np.unique(labels[mask])) <= set(REGIONS.values()) | {1}
    assert len(np.unique(labels[mask])) > 1  # more regions than skin


def test_texture_coordinates_are_where_the_centre_rays_meet_the_face(face):
    """Each pixel's (u, v) on the face: NaN exactly where the ray misses; the texel each names carries the
    region label face_pixels gives; a texture of its own texel coordinates reads them back."""
    model, scene = face
    camera = front_camera(150.0)
    uv = texture_coordinates(scene, camera)
    hit = ~np.isnan(uv[..., 0])
    assert uv.shape == (64, 48, 2)
    np.testing.assert_array_equal(hit, face_pixels(scene, camera, spp=None))
    assert np.all((uv[hit] >= 0) & (uv[hit] <= 1))
    labels = face_pixels(scene, camera, spp=None, region_map=model.region_map)
    np.testing.assert_array_equal(np.maximum(texture_lookup(model.region_map, uv), 1)[hit], labels[hit])
    r = 16
    rows, cols = np.mgrid[0:r, 0:r]
    where = texture_lookup(np.stack([rows, cols], -1), uv)[hit]  # row from v, column from u
    np.testing.assert_array_equal(where[:, 0], np.minimum((uv[hit][:, 1] * r).astype(int), r - 1))
    np.testing.assert_array_equal(where[:, 1], np.minimum((uv[hit][:, 0] * r).astype(int), r - 1))


def test_the_filtered_footprint_takes_in_the_silhouette(face):
    _, scene = face
    centre, filtered = face_pixels(scene, front_camera(150.0), spp=None), face_pixels(scene, front_camera(150.0))
    assert filtered.sum() > centre.sum()
    assert (centre & ~filtered).sum() <= 0.01 * centre.sum()


def test_the_front_of_the_face_is_part_of_the_face(face):
    model, scene = face
    front = front_of_face_pixels(model, model.shape_mean, front_camera(150.0))
    assert 0 < front.sum() < face_pixels(scene, front_camera(150.0)).sum()
    assert not np.any(front & ~face_pixels(scene, front_camera(150.0)))


def test_region_labels_are_those_of_the_centre_rays(face):
    model, scene = face
    with pytest.raises(ValueError, match="spp=None"):
        face_pixels(scene, front_camera(150.0), spp=4, region_map=model.region_map)
