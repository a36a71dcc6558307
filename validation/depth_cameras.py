"""How well one or two calibrated cameras pin a face's depth from clicked feature points (SIMULATED):
a what-if for issue 22's aim of every photograph within 1 mm in the world frame.

Per seed this draws a subject and six head poses as :func:`mifaces.studio.simulate` draws them (the
built-in face, all identity modes at 0.7, a jittered turn and a random expression per pose; not the
same draws as ``simulate``'s seed, whose generator also places lamps and noise), and for each pose
the feature points of :data:`mifaces.model.landmarks.FEATURE_POINTS` that face the camera (vertex
normal towards it: a stand-in for the simulator's ray test). It clicks them as the simulator does
(0.5 px per coordinate at 512 px width) in the studio's camera and, for the what-if, in a second
calibrated camera at the same distance turned by ``--angles`` degrees about the head's vertical axis,
then estimates, over ``--draws`` noise draws:

- ``one_camera``: the true face (shape and size known exactly) posed rigidly on one camera's clicks;
- ``two_cameras_<angle>``: the same on both cameras' clicks;
- ``triangulated_<angle>``: each feature point triangulated from the two cameras, the face unknown.

For each, the error along the first camera's axis of the feature points' centroid (the depth; its
standard deviation and mean absolute value over draws and poses) and the mean distance of the
feature points from the truth. The face's shape is never fitted here: these are the clicks' own
limits, what a shape fit can approach, not what it reaches (the fit's own depth errors are in
``shape_depth.json``).

    python validation/depth_cameras.py --seeds 0 1 2

Writes ``validation/results/depth_cameras.json`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np
import trimesh
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from mifaces.io.atomic import write_json
from mifaces.model import load_model
from mifaces.model.landmarks import FEATURE_POINTS
from mifaces.studio.scene import CAMERA_DISTANCE, FIELD_HEIGHT, head_turns
from mifaces.studio.subject import head_pose, make_subject

RESULTS = Path(__file__).resolve().parent / "results"
#: The simulator's click noise (px per coordinate at 512 px width; mifaces.studio.photograph.annotate).
CLICK_PX = 0.5
#: The photographs' side (px): the default capture's, the resolution the click noise is given at.
SIDE = 512
MEASUREMENTS = 6
#: A feature point is clicked where its vertex normal faces the camera by at least this cosine.
FACING = 0.2


def camera(head: np.ndarray, angle_deg: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The studio camera (``angle_deg`` 0) or one turned about the head's vertical axis:
    ``(R, C, f)`` with ``x_camera = R (x - C)`` in OpenCV axes and the focal length in px."""
    turn = Rotation.from_euler("y", angle_deg, degrees=True).as_matrix()
    rotation = np.diag([1.0, -1.0, -1.0]) @ turn.T
    centre = head + turn @ np.array([0.0, 0.0, CAMERA_DISTANCE])
    return rotation, centre, SIDE * CAMERA_DISTANCE / FIELD_HEIGHT


def project(cam, points: np.ndarray) -> np.ndarray:
    rotation, centre, f = cam
    local = (points - centre) @ rotation.T
    return f * local[:, :2] / local[:, 2:3]


def visible(cam, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    rotation, centre, _ = cam
    towards = centre - points
    towards /= np.linalg.norm(towards, axis=1, keepdims=True)
    return np.einsum("ij,ij->i", towards, normals) > FACING


def pose_on_clicks(points: np.ndarray, cams: list, clicks: list, masks: list) -> np.ndarray:
    """The rigid motion (about the points' centroid) that best puts the known ``points`` on the clicks
    of every camera; returns the moved points."""
    centroid = points.mean(axis=0)

    def moved(x):
        return Rotation.from_rotvec(x[:3]).apply(points - centroid) + centroid + x[3:]

    def residual(x):
        p = moved(x)
        return np.concatenate([(project(c, p[m]) - k).ravel() for c, k, m in zip(cams, clicks, masks)])

    return moved(least_squares(residual, np.zeros(6), x_scale=np.r_[np.full(3, 0.01), np.full(3, 1.0)]).x)


def triangulate(cams: list, clicks: list) -> np.ndarray:
    """Each point from its clicks in two cameras (linear, then refined by least squares)."""
    out = []
    for i in range(len(clicks[0])):
        rows = []
        for (rotation, centre, f), k in zip(cams, clicks):
            P = np.diag([f, f, 1.0]) @ np.hstack([rotation, (-rotation @ centre)[:, None]])
            rows += [k[i, 0] * P[2] - P[0], k[i, 1] * P[2] - P[1]]
        x = np.linalg.svd(np.array(rows))[2][-1]
        start = x[:3] / x[3]
        out.append(least_squares(lambda p: np.concatenate([project(c, p[None])[0] - k[i] for c, k in
                                                           zip(cams, clicks)]), start).x)
    return np.array(out)


def errors(estimate: np.ndarray, truth: np.ndarray, axis: np.ndarray) -> tuple[float, float]:
    """(depth error of the centroid along ``axis``, mean point distance) in mm."""
    return (float((estimate.mean(axis=0) - truth.mean(axis=0)) @ axis),
            float(np.linalg.norm(estimate - truth, axis=1).mean()))


def run_seed(face_model, seed: int, angles: list[float], draws: int) -> dict:
    rng = np.random.default_rng(seed)
    subject = make_subject(face_model, rng, 16)
    names = list(FEATURE_POINTS)
    vertices = [face_model.ibug_landmarks[FEATURE_POINTS[n]] for n in names]
    records: dict[str, list] = {}
    counts = []
    first = camera(subject.head, 0.0)
    axis = first[0][2]  # the first camera's viewing axis in the world frame
    for turn in head_turns(MEASUREMENTS, rng):
        pose = head_pose(face_model, subject, turn, rng)
        normals = trimesh.Trimesh(pose.vertices, face_model.triangles, process=False).vertex_normals[vertices]
        truth = pose.vertices[vertices]
        seen = visible(first, truth, normals)
        counts.append(int(seen.sum()))
        for _ in range(draws):
            click1 = project(first, truth[seen]) + rng.normal(0.0, CLICK_PX, (seen.sum(), 2))
            fit = pose_on_clicks(truth[seen], [first], [click1], [np.ones(seen.sum(), bool)])
            records.setdefault("one_camera", []).append(errors(fit, truth[seen], axis))
            for angle in angles:
                second = camera(subject.head, angle)
                both = (seen & visible(second, truth, normals))[seen]  # of the points the first camera sees
                click2 = project(second, truth[seen][both]) + rng.normal(0.0, CLICK_PX, (both.sum(), 2))
                fit = pose_on_clicks(truth[seen], [first, second], [click1, click2],
                                     [np.ones(seen.sum(), bool), both])
                records.setdefault(f"two_cameras_{angle:g}", []).append(errors(fit, truth[seen], axis))
                pts = triangulate([first, second], [click1[both], click2])
                records.setdefault(f"triangulated_{angle:g}", []).append(errors(pts, truth[seen][both], axis))
    summary = {}
    for key, rows in records.items():
        depth, mean = np.array(rows).T
        summary[key] = {"depth_sd_mm": float(depth.std()), "depth_mean_abs_mm": float(np.abs(depth).mean()),
                        "point_error_mm": float(mean.mean())}
    return {"seed": seed, "feature_points_seen": counts, "estimates": summary}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--angles", type=float, nargs="+", default=[15.0, 30.0, 45.0])
    parser.add_argument("--draws", type=int, default=100)
    parser.add_argument("--out", type=Path, default=RESULTS / "depth_cameras.json")
    args = parser.parse_args(argv)
    face_model = load_model("builtin")
    runs = []
    for seed in args.seeds:
        runs.append(run_seed(face_model, seed, args.angles, args.draws))
        one = runs[-1]["estimates"]["one_camera"]["depth_sd_mm"]
        print(f"seed {seed}: one camera {one:.2f} mm; " + ", ".join(
            f"{k} {v['depth_sd_mm']:.2f} mm" for k, v in runs[-1]["estimates"].items() if k != "one_camera"),
            flush=True)
    keys = list(runs[0]["estimates"])
    pooled = {k: {m: float(np.mean([r["estimates"][k][m] for r in runs])) for m in runs[0]["estimates"][k]}
              for k in keys}
    write_json(args.out, {
        "label": "SIMULATED", "command": "python validation/" + Path(__file__).name + " " + " ".join(sys.argv[1:]),
        "settings": {"click_px_at_512": CLICK_PX, "resolution": SIDE, "camera_distance_mm": CAMERA_DISTANCE,
                     "measurements": MEASUREMENTS, "angles_deg": args.angles, "draws": args.draws,
                     "facing_cosine": FACING},
        "runs": runs, "mean_over_seeds": pooled})


if __name__ == "__main__":
    main()
