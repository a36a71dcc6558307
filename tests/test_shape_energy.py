"""The shape fit's energy (mifaces.shape.energy, paper sec. 4.2) against an independent numpy
evaluation of its terms: E_F from :meth:`Camera.project` (lens distortion included), E_P from the
coefficients, the calibration's focal length, the metric distances and the albedo's spread, E_I from
the one-ring normals of :func:`~mifaces.model.geometry.vertex_normals`, the photographs sampled
bilinearly by scipy, and the Phong shading of Blanz and Vetter (1999, sec. 4) written out here."""

from __future__ import annotations

import dataclasses

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import mitsuba as mi
import numpy as np
import pytest
import scipy.ndimage as ndi

from mifaces.capture import Camera
from mifaces.shape.projection import project as project_on_device
from mifaces.model.geometry import rotation_matrix
from mifaces.model.landmarks import FEATURE_POINTS
from mifaces.shape import Weights, light_direction, rotation_centre
from mifaces.shape.energy import Energy
from mifaces.shape.layout import Layout
from mifaces.shape.targets import FRONTAL

#: Weights unlike each other and unlike the defaults, so that a term given another's weight shows.
WEIGHTS = Weights(image_sigma=0.07, feature_sigma=1.5, feature=1.3, shape=0.2, expression=0.3, albedo=1.7,
                  focal=0.05, distance_sigma=2.0)
#: The lamp of photograph ``point`` at this distance (mm) from the face centre; ``diffuse`` is directional.
LAMP_MM = 900.0
#: Camera intrinsics with every OpenCV distortion coefficient set (fx != fy, cx != cy).
CAMERA = Camera(96, 128, 520.0, 545.0, 46.3, 61.8, np.array([-0.15, 0.08, 0.004, -0.006, 0.03]))


@pytest.fixture(scope="module")
def setup():
    mifaces.set_variant("llvm_ad_rgb")
    model = mifaces.load_model("builtin")
    rng = np.random.default_rng(11)
    h, w = CAMERA.height, CAMERA.width
    rows, cols = np.mgrid[:h, :w]
    images = {key: np.stack([0.5 + 0.3 * np.sin(cols / (5.0 + c) + phase) * np.cos(rows / (7.0 + c))
                             + 0.05 * rng.normal(size=(h, w)) for c in range(3)], axis=2).astype(np.float32)
              for key, phase in (("point", 0.3), ("diffuse", 1.1))}
    layout = Layout(model, list(images))
    theta = np.zeros(layout.size)
    theta[layout["rotation"]] = [0.12, -0.07, 0.05]
    theta[layout["translation"]] = [6.0, -4.0, 1050.0]
    theta[layout["log_focal"]] = 0.03
    for key, angles, colour, ambient in (("point", (0.35, -0.45), (0.9, 0.8, 1.0), (0.1, 0.12, 0.08)),
                                         ("diffuse", (0.1, 0.2), (0.2, 0.25, 0.3), (0.9, 0.8, 0.85))):
        theta[layout[f"{key}.light_angles"]] = angles
        theta[layout[f"{key}.light_color"]] = colour
        theta[layout[f"{key}.ambient"]] = ambient
        theta[layout[f"{key}.specular"]] = 0.3
        theta[layout[f"{key}.contrast"]] = 0.7
        theta[layout[f"{key}.gain"]] = [1.2, 0.9, 1.05]
        theta[layout[f"{key}.offset"]] = [0.02, -0.03, 0.01]
    theta[layout["shape"]] = 0.6 * rng.normal(size=model.shape_dim)
    theta[layout["expression"]] = 0.4 * rng.normal(size=model.expression_dim)
    theta[layout["albedo"]] = (np.array([0.55, 0.42, 0.36]) + 0.15 * rng.normal(size=(model.vertex_count, 3))).ravel()
    ibug = model.ibug_landmarks
    vertices = np.array(sorted({ibug[i] for i in FEATURE_POINTS.values() if i in ibug}), np.int64)
    # the clicked points 2 px (sd) from where the face at theta puts them
    pixels = project(model, layout, theta, vertices) + rng.normal(0.0, 2.0, (len(vertices), 2))
    distances = [(int(vertices[0]), int(vertices[5]), 61.0), (int(vertices[2]), int(vertices[9]), 38.5),
                 (int(vertices[4]), int(vertices[-1]), 95.0)]
    energy = Energy(model, CAMERA, layout, WEIGHTS, images, vertices, pixels, distances, rotation_centre(model),
                    {"point": LAMP_MM}, freeze=False)
    samples = np.sort(rng.choice(np.flatnonzero(model.vertex_regions() != 0), 400, replace=False))
    energy.set_samples(samples)
    seen = (rng.uniform(size=len(samples)) > 0.1).astype(np.float32)
    lit = (rng.uniform(size=len(samples)) > 0.2).astype(np.float32)
    energy.set_visibility(seen, {"point": lit})
    energy.set_level(0.0)
    return model, energy, layout, images, theta, samples, seen, lit


def pose(model, layout, theta):
    """Camera-space vertices (mm) and the camera (focal length scaled by theta's) of ``theta``."""
    rotation = FRONTAL @ rotation_matrix(*np.degrees(theta[layout["rotation"]]))
    vertices = model.shape(theta[layout["shape"]], theta[layout["expression"]]).astype(np.float64)
    focal = np.exp(theta[layout["log_focal"].start])
    camera = dataclasses.replace(CAMERA, fx=CAMERA.fx * focal, fy=CAMERA.fy * focal)  # world = camera frame
    return (vertices - rotation_centre(model)) @ rotation.T + theta[layout["translation"]], rotation, camera


def project(model, layout, theta, vertices):
    """Pixels of model ``vertices`` at ``theta`` (:meth:`Camera.project`)."""
    camera_space, _, camera = pose(model, layout, theta)
    return camera.project(camera_space[vertices])


def reference(model, energy, layout, images, theta, samples, seen, lit):
    """E's terms evaluated in numpy (float64) from their definitions."""

    def block(name):
        return theta[layout[name]]

    shape, expression, t = block("shape"), block("expression"), block("translation")
    camera_space, rotation, camera = pose(model, layout, theta)
    scale_px = CAMERA.height / 512.0
    # E_F: squared distances in pixels at 512 px image height
    uv_features = camera.project(camera_space[energy.feature_vertices])
    sq = np.sum((uv_features - energy.feature_pixels) ** 2, axis=1) / scale_px ** 2
    e_f = sq.mean() / WEIGHTS.feature_sigma ** 2
    # E_P: Mahalanobis norms, log focal length, metric distances on the identity shape, albedo spread
    prior = (theta[layout["log_focal"].start] ** 2 / WEIGHTS.focal ** 2 + WEIGHTS.shape * np.sum(shape ** 2)
             + WEIGHTS.expression * np.sum(expression ** 2))
    identity = model.shape(shape).astype(np.float64)
    lengths = np.array([np.linalg.norm(identity[a] - identity[b]) for a, b, _ in energy.distances])
    e_d = np.mean((lengths - np.array([mm for _, _, mm in energy.distances])) ** 2) / WEIGHTS.distance_sigma ** 2
    albedo = block("albedo").reshape(-1, 3)[samples]
    spread = np.sum((albedo - albedo.mean(axis=0)) ** 2)
    albedo_prior = WEIGHTS.albedo * spread / len(samples)
    e_p = prior + e_d + albedo_prior
    # E_I: Phong shading against the photographs, bilinear at the projected samples
    p = camera_space[samples]
    n = model.vertex_normals(model.shape(shape, expression)).astype(np.float64)[samples] @ rotation.T
    view = -p / np.linalg.norm(p, axis=1, keepdims=True)
    u, v = camera.project(p).T
    inside = (u >= 0) & (u <= CAMERA.width - 1) & (v >= 0) & (v <= CAMERA.height - 1)
    facing = np.maximum(np.sum(n * view, axis=1), 0.0)
    weight = seen * inside * np.clip((facing - 0.1) * 5.0, 0.0, 1.0)
    e_i, num, den = 0.0, 0.0, 0.0
    for key, image in images.items():
        el, az = block(f"{key}.light_angles")
        towards = np.broadcast_to(light_direction(el, az), p.shape)
        colour_l = np.broadcast_to(block(f"{key}.light_color"), p.shape)
        shadow = lit if key == "point" else np.ones(len(p))
        if key == "point":  # the lamp at its distance: per-point direction, inverse-square falloff
            to_lamp = t + LAMP_MM * towards - p
            d2 = np.sum(to_lamp ** 2, axis=1, keepdims=True)
            towards, colour_l = to_lamp / np.sqrt(d2), colour_l * LAMP_MM ** 2 / d2
        ndl = np.sum(n * towards, axis=1)
        mirror = 2 * ndl[:, None] * n - towards
        specular = block(f"{key}.specular")[0] * np.maximum(np.sum(mirror * view, axis=1), 0.0) ** 16
        diffuse = block(f"{key}.ambient") + colour_l * (np.maximum(ndl, 0.0) * shadow)[:, None]
        colour = albedo * diffuse + colour_l * (specular * shadow * (ndl > 0))[:, None]
        luminance = colour @ np.array([0.3, 0.59, 0.11])
        colour = luminance[:, None] + block(f"{key}.contrast")[0] * (colour - luminance[:, None])
        colour = block(f"{key}.gain") * colour + block(f"{key}.offset")
        observed = np.stack([ndi.map_coordinates(image[..., c].astype(np.float64), [v, u], order=1, mode="nearest")
                             for c in range(3)], axis=1)
        residual = np.sum((colour - observed) ** 2, axis=1)
        e_i += np.sum(weight * residual) / max(np.sum(weight), 1.0)
        num, den = num + np.sum(weight * residual), den + np.sum(weight)
    e_i /= len(images) * WEIGHTS.image_sigma ** 2
    return {"E_F": e_f, "E_P": e_p, "E_D": e_d, "E_I": e_i, "albedo_prior": albedo_prior,
            "feature_rms_px": np.sqrt(sq.mean()) * scale_px, "image_rms": np.sqrt(num / den / 3.0),
            "inside": inside.mean(), "weighted": np.mean(weight > 0)}


def test_energy_terms_match_an_independent_evaluation(setup):
    model, energy, layout, images, theta, samples, seen, lit = setup
    expected = reference(model, energy, layout, images, theta, samples, seen, lit)
    assert 0.8 < expected["inside"] < 1 and expected["weighted"] > 0.3  # the face is in the picture, mostly facing
    feature_weight, image_weight = 0.7, 0.6
    terms, grad = energy.evaluate(theta, feature_weight, image_weight)
    for name in ("E_F", "E_P", "E_D", "E_I", "feature_rms_px", "image_rms"):
        assert terms[name] == pytest.approx(expected[name], rel=1e-4), name
    total = image_weight * expected["E_I"] + feature_weight * WEIGHTS.feature * expected["E_F"] + expected["E_P"]
    assert terms["E"] == pytest.approx(total, rel=1e-4)
    assert np.all(np.isfinite(grad)) and np.any(grad[layout["shape"]] != 0)
    # without the image term neither E_I nor the albedo's prior (the albedo enters nothing else) is evaluated
    terms, _ = energy.evaluate(theta, feature_weight, 0.0, grad=False)
    rest = feature_weight * WEIGHTS.feature * expected["E_F"] + expected["E_P"] - expected["albedo_prior"]
    assert expected["albedo_prior"] > 1e-3 * rest and terms["E"] == pytest.approx(rest, rel=1e-4)


def test_energy_projects_as_the_camera(setup):
    """The energy's copy of the projection (on the Dr.Jit side) against :meth:`Camera.project`, over
    a field as wide as a short lens sees (45 degrees off the axis, where every distortion term shows)."""
    energy = setup[1]
    rng = np.random.default_rng(5)
    depth = rng.uniform(300.0, 2000.0, 500)
    points = np.column_stack([rng.uniform(-1.0, 1.0, (500, 2)) * depth[:, None], depth])
    u, v = project_on_device([mi.Float(c.astype(np.float32)) for c in points.T], mi.Float(1.1), energy.camera)
    camera = dataclasses.replace(CAMERA, fx=CAMERA.fx * 1.1, fy=CAMERA.fy * 1.1)
    np.testing.assert_allclose(np.column_stack([np.array(u), np.array(v)]), camera.project(points), rtol=1e-5,
                               atol=1e-3)
