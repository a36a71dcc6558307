"""Shape estimation on simulated captures, against ground truth and against eos.

For the default simulated capture (built-in model, 512 x 512, 6 measurements,
``mifaces.studio.simulate.simulate`` defaults) and the same capture simulated with
the Surrey Face Model (``../shared/models/sfm_3448``), every measurement is
fitted with :func:`mifaces.shape.fit.fit_shape` (paper sec. 4.2) and
with eos's landmark-only fit (``eos.fitting.fit_shape_and_pose`` with the
SFM, its expression blendshapes, landmark mapper and contours: the peer
baseline, given the same feature points). Reported per measurement and on
average:

* ``landmark_px`` -- mean distance (px) between the fitted model's feature
  points, projected (mifaces: the calibrated camera; eos: its affine camera),
  and their exact projections in the ground truth (not the noisy clicks
  the fit was given);
* ``vertex_rms_mm`` -- RMS distance of the fitted vertices from the ground
  truth in the world frame (mifaces only: eos's orthographic camera has no
  depth); ``vertex_rms_aligned_mm`` -- the same after the best rigid motion
  (the shape error alone);
* ``normal_deg`` -- mean angle between fitted and true vertex normals in the
  camera frame (each method's own rotation); ``normal_aligned_deg`` -- after
  the rigid alignment. The paper's 6.3 deg is the deviation of its
  reconstructions of one head from their mean.

Evaluated vertices: the ground-truth face's vertices that face the camera
(``n . v > 0.1``) outside the region map's background. On the built-in
capture eos fits a different mesh (the SFM's 3448 vertices): it is aligned
rigidly to the truth (feature points, then 10 ICP steps) and compared at the
nearest vertex, over the truth's vertices it covers (within 5 mm); the
mifaces fit is scored the same way on the same vertices (``*_nn`` columns)
for a like-for-like comparison. "mean face" is the model's mean shape at
the true pose: what a fit that gets the pose exactly and learns nothing
about the shape would score.

Then the BRDF estimation (``mifaces.reflectance.estimate.fit_brdf``, Cook-Torrance,
256 x 256 texture) on the fitted shapes instead of the true ones: how much the
per-region parameter errors and the albedo error grow. Last, the error against
run time of one measurement (m00 of the default capture) for several
iteration budgets at 512 x 512 and 256 x 256.

Run:  python validation/shape_estimation.py [--quick] [--work DIR]
Writes validation/results/shape_estimation.{json,png} and prints a table.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np
from scipy.spatial import cKDTree

from mifaces import shape as se
from mifaces.capture import load_capture, read_ground_truth
from mifaces.io.atomic import save_figure, write_json
from mifaces.model.landmarks import FEATURE_POINTS
from mifaces.reflectance import FitOptions

OUT = Path(__file__).resolve().parent / "results"
SFM = Path(__file__).resolve().parents[2] / "shared" / "models" / "sfm_3448"
if not SFM.is_dir():
    SFM = Path("/work/shared/models/sfm_3448")
TARGET_NORMAL_DEG = 6.3
TARGET_LANDMARK_PX = 2.0


# --------------------------------------------------------------------------------------------
# Ground truth and metrics
# --------------------------------------------------------------------------------------------
def ensure_capture(path: Path, **kw) -> Path:
    from mifaces.studio import SimulationOptions, simulate

    if not (path / "capture.json").is_file():
        print(f"simulating {path} {kw}", flush=True)
        simulate(path, SimulationOptions(**kw), progress=False)
    return path


def truth(capture_path: Path, name: str):
    """The true vertices (world, mm) of measurement ``name`` and its ground-truth record."""
    gt = read_ground_truth(capture_path)
    entry = next(m for m in gt.measurements if m.name == name)
    return entry.vertices.astype(np.float64), entry, gt.head_center


def evaluated(model, vertices_world, camera) -> np.ndarray:
    """Vertices of the true face that count: facing the camera, outside the background region."""
    n = model.vertex_normals(vertices_world)
    view = camera.position - vertices_world
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    return (model.vertex_regions() != 0) & (np.sum(n * view, axis=1) > 0.1)


def kabsch(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid motion (R, t) minimising ||R src + t - dst||."""
    cs, cd = src.mean(0), dst.mean(0)
    u, _, vt = np.linalg.svd((src - cs).T @ (dst - cd))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1, 1, d]) @ u.T
    return r, cd - r @ cs


def angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0)))


def same_topology_metrics(model, fitted_world, truth_world, camera, mask, fitted_rotation=None) -> dict:
    """Per-vertex metrics of a fit with the truth's topology."""
    nt = model.vertex_normals(truth_world)
    nf = model.vertex_normals(fitted_world)
    out = {}
    if fitted_rotation is None:  # vertices already in the world frame: absolute errors
        out["vertex_rms_mm"] = float(np.sqrt(np.mean(np.sum((fitted_world - truth_world) ** 2, 1)[mask])))
        out["normal_deg"] = float(angles(nf, nt)[mask].mean())
    r, t = kabsch(fitted_world[mask], truth_world[mask])
    aligned = fitted_world @ r.T + t
    out["vertex_rms_aligned_mm"] = float(np.sqrt(np.mean(np.sum((aligned - truth_world) ** 2, 1)[mask])))
    out["normal_aligned_deg"] = float(angles(nf @ r.T, nt)[mask].mean())
    return out


def landmark_error(points: dict, project, vertices, ibug) -> float:
    errs = [np.linalg.norm(project(vertices[ibug[FEATURE_POINTS[n]]]) - np.asarray(p))
            for n, p in points.items() if FEATURE_POINTS[n] in ibug]
    return float(np.mean(errs))


def nearest_metrics(truth_model, truth_world, mask, mesh_vertices, mesh_normals, landmark_pairs,
                    covered=None) -> tuple[dict, np.ndarray]:
    """Metrics of a fit on another mesh: rigid alignment (landmarks, then ICP), nearest vertex."""
    src = np.array([mesh_vertices[a] for a, _ in landmark_pairs])
    dst = np.array([truth_world[b] for _, b in landmark_pairs])
    r, t = kabsch(src, dst)
    target = truth_world[mask]
    tree = cKDTree(target)
    for _ in range(10):
        moved = mesh_vertices @ r.T + t
        d, i = tree.query(moved)
        keep = d < 10.0
        r, t = kabsch(mesh_vertices[keep], target[i[keep]])
    moved = mesh_vertices @ r.T + t
    d, j = cKDTree(moved).query(truth_world)
    covered = mask & (d < 5.0) if covered is None else covered
    nt = truth_model.vertex_normals(truth_world)
    return ({"vertex_rms_aligned_nn_mm": float(np.sqrt(np.mean(d[covered] ** 2))),
             "normal_aligned_nn_deg": float(angles(mesh_normals[j] @ r.T, nt)[covered].mean()),
             "covered_vertices": int(covered.sum())}, covered)


# --------------------------------------------------------------------------------------------
# eos, the landmark-only peer
# --------------------------------------------------------------------------------------------
class Eos:
    def __init__(self):
        import eos

        self.eos = eos
        shape = eos.morphablemodel.load_model(str(SFM / "sfm_shape_3448.bin"))
        blendshapes = eos.morphablemodel.load_blendshapes(str(SFM / "expression_blendshapes_3448.bin"))
        self.model = eos.morphablemodel.MorphableModel(
            shape.get_shape_model(), blendshapes, color_model=eos.morphablemodel.PcaModel(),
            vertex_definitions=None, texture_coordinates=shape.get_texture_coordinates())
        self.mapper = eos.core.LandmarkMapper(str(SFM / "ibug_to_sfm.txt"))
        self.edges = eos.morphablemodel.load_edge_topology(str(SFM / "sfm_3448_edge_topology.json"))
        self.contour = eos.fitting.ContourLandmarks.load(str(SFM / "ibug_to_sfm.txt"))
        self.model_contour = eos.fitting.ModelContour.load(str(SFM / "sfm_model_contours.json"))
        self.sfm = mifaces.load_model(SFM / "sfm_shape_3448.npz")

    def fit(self, measurement, camera) -> dict:
        eos = self.eos
        landmarks = [eos.core.Landmark(str(FEATURE_POINTS[n]), np.asarray(p, np.float32))
                     for n, p in measurement.feature_points.items()]
        t0 = time.perf_counter()
        mesh, rp, shape, _ = eos.fitting.fit_shape_and_pose(
            self.model, landmarks, self.mapper, camera.width, camera.height, self.edges, self.contour,
            self.model_contour)
        seconds = time.perf_counter() - t0
        vertices = np.array(mesh.vertices, np.float64)
        affine = np.array(eos.fitting.get_3x4_affine_camera_matrix(rp, camera.width, camera.height))
        rotation = np.diag([1.0, -1.0, -1.0]) @ np.array(rp.get_modelview())[:3, :3]  # OpenGL -> OpenCV
        return {"vertices": vertices, "affine": affine, "rotation_camera": rotation, "seconds": seconds,
                "yaw_pitch_roll": np.array(rp.get_yaw_pitch_roll(), np.float64)}


# --------------------------------------------------------------------------------------------
# One capture
# --------------------------------------------------------------------------------------------
def run_capture(label: str, path: Path, model_source, eos: Eos, iterations, out_dir: Path) -> dict:
    capture = load_capture(path)
    model = mifaces.load_model(model_source)
    camera = capture.camera
    t0 = time.perf_counter()
    fits = se.fit_shape(capture, model, out=out_dir / label, iterations=iterations, progress=False)
    total = time.perf_counter() - t0
    same = model.name == eos.sfm.name
    rows = {}
    for fit, m in zip(fits, capture.measurements):
        gt, entry, head_center = truth(path, m.name)
        mask = evaluated(model, gt, camera)
        ibug = model.ibug_landmarks
        # mifaces
        ours = {"status": fit.status, "seconds": fit.seconds, "iterations": fit.iterations,
                "landmark_px": landmark_error(entry.feature_points, camera.project, fit.vertices_world, ibug),
                **same_topology_metrics(model, fit.vertices_world.astype(np.float64), gt, camera, mask)}
        ours["yaw_pitch_roll_error_deg"] = (fit.yaw_pitch_roll - np.asarray(entry.yaw_pitch_roll)).tolist()
        # the mean face at the true pose
        rot, head, tr = (np.asarray(entry.rotation), np.asarray(head_center),
                         np.asarray(entry.translation))
        mean_world = (model.shape_mean.astype(np.float64) - head) @ rot.T + head + tr
        mean_face = {"landmark_px": landmark_error(entry.feature_points, camera.project, mean_world, ibug),
                     **same_topology_metrics(model, mean_world, gt, camera, mask)}
        # eos
        e = eos.fit(m, camera)

        def eos_project(p, a=e["affine"]):
            return a[:2, :3] @ p + a[:2, 3]

        sfm_ibug = eos.sfm.ibug_landmarks
        theirs = {"seconds": e["seconds"],
                  "landmark_px": landmark_error(entry.feature_points, eos_project, e["vertices"], sfm_ibug)}
        eos_normals_model = eos.sfm.vertex_normals(e["vertices"])
        gt_normals_camera = model.vertex_normals(gt) @ camera.rotation.T
        if same:
            theirs.update(same_topology_metrics(model, e["vertices"], gt, camera, mask, fitted_rotation=True))
            theirs["normal_deg"] = float(angles(eos_normals_model @ e["rotation_camera"].T,
                                                gt_normals_camera)[mask].mean())
        pairs_eos = [(sfm_ibug[i], ibug[i]) for i in FEATURE_POINTS.values() if i in sfm_ibug and i in ibug]
        nn_eos, covered = nearest_metrics(model, gt, mask, e["vertices"], eos_normals_model, pairs_eos)
        theirs.update(nn_eos)
        if not same:
            # absolute normals through eos's rotation, at the nearest vertex after alignment
            r, t = kabsch(np.array([e["vertices"][a] for a, _ in pairs_eos]), np.array([gt[b] for _, b in pairs_eos]))
            _, j = cKDTree(e["vertices"] @ r.T + t).query(gt)
            theirs["normal_deg"] = float(angles(eos_normals_model[j] @ e["rotation_camera"].T,
                                                gt_normals_camera)[covered].mean())
        pairs_ours = [(v, v) for v in ibug.values()]
        ours.update(nearest_metrics(model, gt, mask, fit.vertices_world.astype(np.float64),
                                    model.vertex_normals(fit.vertices_world), pairs_ours, covered=covered)[0])
        ours["normal_deg_covered"] = float(angles(model.vertex_normals(fit.vertices_world),
                                                  model.vertex_normals(gt))[covered].mean())
        mean_face.update(nearest_metrics(model, gt, mask, mean_world, model.vertex_normals(mean_world),
                                         pairs_ours, covered=covered)[0])
        rows[m.name] = {"mifaces": ours, "eos": theirs, "mean_face": mean_face}
        print(f"  {label} {m.name}: mifaces {fit.status} {fit.seconds:.1f}s lm {ours['landmark_px']:.2f}px "
              f"normal {ours['normal_deg']:.2f} deg (nn {ours['normal_aligned_nn_deg']:.2f}) "
              f"vRMS {ours['vertex_rms_mm']:.1f} mm (aligned {ours['vertex_rms_aligned_mm']:.2f}) | eos lm "
              f"{theirs['landmark_px']:.2f}px normal {theirs['normal_deg']:.2f} (nn "
              f"{theirs['normal_aligned_nn_deg']:.2f}) | mean face normal {mean_face['normal_deg']:.2f}",
              flush=True)
    summary = {}
    for method in ("mifaces", "eos", "mean_face"):
        keys = sorted({k for r in rows.values() for k, v in r[method].items() if isinstance(v, (int, float))})
        summary[method] = {k: float(np.mean([r[method][k] for r in rows.values() if k in r[method]])) for k in keys}
    summary["mifaces"]["converged"] = sum(r["mifaces"]["status"] == "converged" for r in rows.values())
    return {"path": str(path), "model": model.name, "resolution": [camera.width, camera.height],
            "measurements": rows, "summary": summary, "fit_seconds_total": total}


def sweep(path: Path, model_source, factors, name="m00") -> list[dict]:
    """Error of one measurement's fit against its run time, for several iteration budgets."""
    capture = load_capture(path)
    model = mifaces.load_model(model_source)
    m = next(x for x in capture.measurements if x.name == name)
    gt, entry, head_center = truth(path, name)
    mask = evaluated(model, gt, capture.camera)
    out = []
    for factor in factors:
        fit = se.fit_measurement(m, capture.camera, model, light=capture.light(m.light),
                                 schedule=se.ShapeSchedule.scaled(factor), progress=False, distances=capture.distances)
        row = {"resolution": capture.camera.width, "factor": factor, "iterations": fit.iterations,
               "seconds": fit.seconds, "status": fit.status,
               "landmark_px": landmark_error(entry.feature_points, capture.camera.project, fit.vertices_world,
                                             model.ibug_landmarks),
               **same_topology_metrics(model, fit.vertices_world.astype(np.float64), gt, capture.camera, mask)}
        print(f"  sweep {capture.camera.width}px x{factor}: {fit.iterations} it {fit.seconds:.1f}s "
              f"lm {row['landmark_px']:.2f}px normal {row['normal_deg']:.2f} deg vRMS {row['vertex_rms_mm']:.1f}",
              flush=True)
        out.append(row)
    return out


def brdf_growth(path: Path, fits: Path, model_source, resolution: int = 256) -> dict:
    """Cook-Torrance fits (``mifaces.reflectance.estimate.fit_brdf``) with the true and with the fitted
    shapes: per region the relative errors of rho_s (mean over RGB) and roughness against the
    simulator's truth, and the RMSE of the refined albedo against the true albedo map."""
    import warnings

    from skimage.transform import resize

    from mifaces.reflectance.estimate import fit_brdf

    capture = load_capture(path)
    model = mifaces.load_model(model_source)
    ground_truth = read_ground_truth(path)
    truth_brdf, albedo_truth = ground_truth.brdf, ground_truth.albedo
    out = {}
    for label, geometry in (("true_shapes", "ground-truth"), ("fitted_shapes", fits)):
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est = fit_brdf(capture, "cooktorrance", geometry=str(geometry), face_model=model, progress=False,
                           options=FitOptions(resolution=resolution))
        truth_map = resize(albedo_truth, (resolution, resolution, 3), anti_aliasing=True, order=1)
        seen = est.albedo.samples > 0
        row = {"seconds": time.perf_counter() - t0, "samples": int(est.samples),
               "albedo_rmse": float(np.sqrt(np.mean((est.albedo.albedo - truth_map)[seen] ** 2))), "regions": {}}
        for name in ("skin", "beard", "lips", "hair"):
            if name not in est.fits or name not in truth_brdf["regions"]:
                continue
            fit, true = est.fits[name].params, truth_brdf["regions"][name]
            row["regions"][name] = {
                "specular_reflectance_rel": float(np.mean(np.abs(np.asarray(fit["specular_reflectance"]) /
                                                                 np.asarray(true["specular_reflectance"]) - 1))),
                "roughness_rel": float(abs(float(fit["roughness"]) / true["roughness"] - 1))}
        out[label] = row
    print(f"  BRDF {path.name}: albedo RMSE {out['true_shapes']['albedo_rmse']:.4f} (true shapes) -> "
          f"{out['fitted_shapes']['albedo_rmse']:.4f} (fitted); skin rho_s "
          f"{out['true_shapes']['regions']['skin']['specular_reflectance_rel']:.3f} -> "
          f"{out['fitted_shapes']['regions']['skin']['specular_reflectance_rel']:.3f}, roughness "
          f"{out['true_shapes']['regions']['skin']['roughness_rel']:.3f} -> "
          f"{out['fitted_shapes']['regions']['skin']['roughness_rel']:.3f}", flush=True)
    return out


def figure(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for res, marker in ((512, "o-"), (256, "s--")):
        rows = [r for r in result["sweep"] if r["resolution"] == res]
        if not rows:
            continue
        t = [r["seconds"] for r in rows]
        for ax, key in zip(axes, ("normal_deg", "landmark_px", "vertex_rms_aligned_mm")):
            ax.plot(t, [r[key] for r in rows], marker, label=f"mifaces {res} px")
            for r in rows:
                ax.annotate(str(r["iterations"]), (r["seconds"], r[key]), fontsize=7)
    default = result["captures"]["builtin"]["summary"]
    for ax, key, eos_key in zip(axes, ("normal_deg", "landmark_px", "vertex_rms_aligned_mm"),
                                ("normal_deg", "landmark_px", "vertex_rms_aligned_nn_mm")):
        ax.axhline(default["eos"][eos_key], color="C3", ls=":",
                   label="eos (landmarks only)" + (", nearest vertex" if "nn" in eos_key else ""))
        ax.axhline(default["mean_face"][key], color="gray", ls="-.", label="mean face at true pose")
        ax.set_xlabel("seconds per image (this machine)")
        ax.set_xscale("log")
    axes[0].axhline(TARGET_NORMAL_DEG, color="k", lw=0.8, label="paper: 6.3 deg")
    axes[1].axhline(TARGET_LANDMARK_PX, color="k", lw=0.8, label="target 2 px")
    axes[0].set_ylabel("mean normal deviation (deg)")
    axes[1].set_ylabel("landmark error (px at 512)")
    axes[2].set_ylabel("vertex RMS after rigid alignment (mm)")
    axes[0].legend(fontsize=7)
    axes[1].legend(fontsize=7)
    fig.suptitle("Shape estimation (paper sec. 4.2), measurement m00 of the default simulated capture; "
                 "labels: iterations")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def brdf_table(result: dict) -> str:
    lines = [f"{'capture':8} {'shapes':14} {'albedo RMSE':>11} " +
             " ".join(f"{r + ' rho_s':>12} {r + ' rough.':>12}" for r in ("skin", "beard", "lips"))]
    for label, rows in result["brdf"].items():
        for shapes, row in rows.items():
            cells = []
            for r in ("skin", "beard", "lips"):
                e = row["regions"].get(r, {})
                cells.append(f"{e.get('specular_reflectance_rel', float('nan')):>12.3f} "
                             f"{e.get('roughness_rel', float('nan')):>12.3f}")
            lines.append(f"{label:8} {shapes:14} {row['albedo_rmse']:>11.4f} " + " ".join(cells))
    return "\n".join(lines)


def table(result: dict) -> str:
    lines = [f"{'capture':8} {'method':10} {'landmark px':>11} {'vRMS mm':>8} {'vRMS al.':>8} {'normal deg':>10} "
             f"{'normal al.':>10} {'normal nn':>9} {'s/image':>8}"]

    def f(d, k, fmt="{:.2f}"):
        return fmt.format(d[k]) if k in d else "-"

    for label, cap in result["captures"].items():
        for method in ("mifaces", "eos", "mean_face"):
            s = cap["summary"][method]
            lines.append(f"{label:8} {method:10} {f(s, 'landmark_px'):>11} {f(s, 'vertex_rms_mm'):>8} "
                         f"{f(s, 'vertex_rms_aligned_mm'):>8} {f(s, 'normal_deg'):>10} "
                         f"{f(s, 'normal_aligned_deg'):>10} {f(s, 'normal_aligned_nn_deg'):>9} "
                         f"{f(s, 'seconds', '{:.1f}'):>8}")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/mifaces-validation-shape"),
                        help="folder for the simulated captures and the fitted shapes")
    parser.add_argument("--quick", action="store_true", help="half the iterations, a shorter sweep")
    parser.add_argument("--iterations", type=float, default=None,
                        help="factor on the default schedule's iterations (default 1, 0.5 with --quick)")
    args = parser.parse_args()
    work = args.work
    t0 = time.perf_counter()
    builtin = ensure_capture(work / "builtin_512")
    surrey = ensure_capture(work / "sfm_512", model=str(SFM / "sfm_shape_3448.npz"))
    small = ensure_capture(work / "builtin_256", resolution=(256, 256))
    factor = args.iterations or (0.5 if args.quick else 1.0)
    eos = Eos()
    result = {"command": "python " + " ".join(["validation/shape_estimation.py"] + sys.argv[1:]),
              "schedule": {"levels": [list(level) for level in se.ShapeSchedule.scaled(factor).levels],
                           "pose_iterations": se.ShapeSchedule.scaled(factor).pose_iterations},
              "weights": se.Weights().__dict__, "captures": {}}
    result["captures"]["builtin"] = run_capture("builtin", builtin, "builtin", eos, factor, work / "fits")
    result["captures"]["sfm"] = run_capture("sfm", surrey, str(SFM / "sfm_shape_3448.npz"), eos, factor,
                                            work / "fits")
    result["brdf"] = {
        "builtin": brdf_growth(builtin, work / "fits" / "builtin", "builtin"),
        "sfm": brdf_growth(surrey, work / "fits" / "sfm", str(SFM / "sfm_shape_3448.npz"))}
    factors = tuple(f * factor for f in ((0.25, 0.5, 1.0) if args.quick else (0.25, 0.5, 1.0, 2.0)))
    result["sweep"] = sweep(builtin, "builtin", factors) + sweep(small, "builtin", factors[:3])
    b = result["captures"]["builtin"]["summary"]
    result["targets"] = {
        "normal_below_6.3_deg": b["mifaces"]["normal_deg"] < TARGET_NORMAL_DEG,
        "normal_below_eos": b["mifaces"]["normal_deg"] < b["eos"]["normal_deg"],
        "normal_nn_below_eos_nn": b["mifaces"]["normal_aligned_nn_deg"] < b["eos"]["normal_aligned_nn_deg"],
        "landmark_below_2_px": b["mifaces"]["landmark_px"] < TARGET_LANDMARK_PX}
    result["seconds"] = time.perf_counter() - t0
    OUT.mkdir(parents=True, exist_ok=True)
    write_json(OUT / "shape_estimation.json", result)
    figure(result, OUT / "shape_estimation.png")
    print(table(result))
    print("BRDF (Cook-Torrance, relative errors against the truth):")
    print(brdf_table(result))
    print("targets:", result["targets"])
    print(f"wrote {OUT / 'shape_estimation.json'} and .png in {result['seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
