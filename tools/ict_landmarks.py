"""Choose the built-in model's 68 landmark vertices where dlib's detector puts the iBUG points.

The toolkit's landmark vertices follow its own annotation; the 68-point
detector mifaces uses on real photographs (dlib's iBUG predictor) puts some
points elsewhere (the brows on their upper edge, the eye corners, the nose
bridge). A shape fit pulls each model landmark onto the detected point, so a
different definition bends the fitted face (on the Yale photographs it
pitched frontal faces down). This script renders the mean face and random
faces of the converted model (identities drawn from the prior, a seed used for
nothing else) in several poses, detects the 68 points on each render, and for
each landmark picks the face vertex, within 15 mm of the toolkit's, whose
projections lie nearest the detections in the mean over all renders (the
jaw contour, 1-17, over the frontal renders only: it is a silhouette).
It prints the table for ``mifaces.model.ict_convert.LANDMARKS`` (the
toolkit's vertex indices) and the mean pixel distances before and after::

    python tools/ict_landmarks.py            # after python -m mifaces.model.ict_convert ...

Needs the ``landmarks`` extra (dlib).
"""

from __future__ import annotations

import sys

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip
import numpy as np

from mifaces.brdf.model import rgb
from mifaces.capture import Camera
from mifaces.capture.detector import detect_landmarks
from mifaces.model import load_model
from mifaces.model.geometry import head_centre, rotation_matrix
from mifaces.model.ict_convert import ATLAS
from mifaces.model.mesh import mitsuba_mesh
from mifaces.model.regions import REGIONS
from mifaces.render import mitsuba_sensor

SEED = 31
FACES = 6
POSES = [(0, 0), (-15, 0), (15, 0), (0, -10), (0, 10)]
SIZE = 512
RADIUS_MM = 15.0
CAP_PX = 8.0
COLOURS = {"skin": (0.55, 0.38, 0.3), "lips": (0.5, 0.18, 0.16), "eyebrows": (0.05, 0.035, 0.025),
           "eyes": (0.75, 0.72, 0.68), "beard": (0.5, 0.35, 0.28), "nostrils": (0.2, 0.1, 0.08),
           "hair": (0.08, 0.06, 0.05)}


def render(model, vertices, albedo, camera):
    import mitsuba as mi

    mifaces.set_variant("llvm_ad_rgb")
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 3},
                          "sensor": mitsuba_sensor(camera, 16),
                          "face": mitsuba_mesh(vertices, model.triangles, model.uv, albedo=albedo),
                          "key": {"type": "point", "position": (camera.position + [300.0, 400.0, 0.0]).tolist(),
                                  "intensity": rgb(1.2e6)},
                          "fill": {"type": "constant", "radiance": rgb(0.25)}})
    image = np.array(mi.render(scene), np.float64)
    return np.clip(image, 0, 1) ** (1 / 2.2)


def albedo_of(model):
    labels = model.vertex_regions()
    out = np.tile(np.array(COLOURS["skin"]), (model.vertex_count, 1))
    for name, colour in COLOURS.items():
        out[labels == REGIONS[name]] = colour
    # a dark iris and pupil: eye vertices near each eye's forward axis
    p = model.shape_mean
    for ids in (range(37, 43), range(43, 49)):
        centre = np.mean([p[model.ibug_landmarks[i]] for i in ids], axis=0)
        near = (labels == REGIONS["eyes"]) & (np.linalg.norm(p[:, :2] - centre[:2], axis=1) < 5.6) & \
               (p[:, 2] > centre[2] - 8) & (np.sign(p[:, 0]) == np.sign(centre[0]))
        out[near] = (0.06, 0.04, 0.03)
    return out


def main() -> int:
    model = load_model("builtin")
    rng = np.random.default_rng(SEED)
    albedo = albedo_of(model)
    face_part = model.uv[:, 0] < ATLAS["M_Face"][0][2]
    candidates = {}
    for i, v in model.ibug_landmarks.items():
        d = np.linalg.norm(model.shape_mean - model.shape_mean[v], axis=1)
        candidates[i] = np.flatnonzero(face_part & (d < RADIUS_MM))
    sums = {i: np.zeros(len(c)) for i, c in candidates.items()}
    counts = {i: 0 for i in candidates}
    before = []
    for f in range(FACES):
        coefficients = None if f == 0 else 0.7 * rng.standard_normal(model.shape_dim)
        neutral = model.shape(coefficients).astype(np.float64)
        centre = head_centre(neutral, model.ibug_landmarks)
        for yaw, pitch in POSES:
            vertices = (neutral - centre) @ rotation_matrix(yaw, pitch, 0.0).T
            rotation = np.diag([1.0, -1.0, -1.0])
            fy = SIZE * 1200.0 / 300.0
            camera = Camera(SIZE, SIZE, fy, fy, SIZE / 2 - 0.5, SIZE / 2 - 0.5, np.zeros(5), rotation,
                            -rotation @ np.array([0.0, 0.0, 1200.0]))
            image = render(model, vertices, albedo, camera)
            try:
                detected = detect_landmarks(image).points
            except Exception as error:  # a pose the detector misses is left out
                print(f"face {f} yaw {yaw} pitch {pitch}: {error}")
                continue
            frontal = yaw == 0 and pitch == 0
            for i, c in candidates.items():
                if i <= 17 and not frontal:
                    continue
                xy = camera.project(vertices[c])
                # squared distance, capped: a render where the detector strays does not decide
                sums[i] += np.minimum(np.sum((xy - detected[i - 1]) ** 2, axis=1), CAP_PX ** 2)
                counts[i] += 1
                before.append((i, float(np.linalg.norm(camera.project(vertices[[model.ibug_landmarks[i]]])[0]
                                                       - detected[i - 1]))))
            print(f"face {f} yaw {yaw:+d} pitch {pitch:+d}: detected", flush=True)
    chosen = {}
    for i, c in candidates.items():
        chosen[i] = int(c[np.argmin(sums[i])]) if counts[i] else model.ibug_landmarks[i]
    rms_after = {i: float(np.sqrt(np.min(sums[i]) / max(counts[i], 1))) for i in candidates}
    rms_before = {i: float(np.sqrt(np.mean([min(e, CAP_PX) ** 2 for j, e in before if j == i]))) for i in candidates}
    print(f"landmark: rms px (distances capped at {CAP_PX:g} px) before -> after")
    for i in sorted(candidates):
        print(f"  {i:2d}: {rms_before[i]:5.1f} -> {rms_after[i]:5.1f}")
    print(f"mean over landmarks: {np.mean(list(rms_before.values())):.2f} -> {np.mean(list(rms_after.values())):.2f} px")
    # back to the toolkit's vertex indices (the converter's table)
    import json

    from mifaces.model.ict_convert import source_vertices

    toolkit = source_vertices()
    print("LANDMARKS = " + json.dumps([int(toolkit[chosen[i]]) for i in range(1, 69)]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
