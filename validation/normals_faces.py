"""Per-texel normals on a SIMULATED face capture: skin gloss with and without them.

The Surrey Face Model capture of ``validation/shape_estimation.py`` (512 x 512
photographs, 6 measurements: 2 lights x 3 poses, Cook-Torrance ground truth,
seed 0) is fitted with ``mifaces.shape.fit_shape``; the Cook-Torrance BRDF is
then fitted per region at a 256 x 256 texture (``fit_brdf``):

* ``true_shapes``: the simulator's shapes, no normal refinement;
* ``fitted``: the fitted shapes, no normal refinement (issue 13: 34 % / 8 %);
* ``fitted_normals``: the fitted shapes, ``fit_brdf(..., options=FitOptions(normals=True))``;
* ``fitted_offsets_only``: the same alternation with the normals held at the
  model's (prior weight 1e6): what the albedo offsets and the choice of
  samples do without any normal moving (an ablation);
* ``true_shapes_normals``: the true shapes with normals (should change little).

Reported: skin ρ_s (mean over RGB) and roughness relative errors against the
truth; the per-texel ρ_s map (``specular_maps=True``) on skin texels with 3 or
more samples: its spread about the region's fit (the truth has one ρ_s per
region, so it should stay near it) and its error against the truth; and for
the refined skin texels the mean angle between the normal used and the true
one, expressed in the fitted shape's tangent frame and averaged over the
measurements (the part of the shape fit's normal error that a tangent-space
normal map can correct).

Run:  python validation/normals_faces.py [--work DIR] [--resolution 256]
Writes validation/results/normals_faces.{json,png}. SIMULATED data.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import numpy as np

from mifaces.capture import load_capture, read_ground_truth
from mifaces.io.atomic import save_figure, write_json
from mifaces.shape.io import load_geometry
from mifaces.model.regions import REGIONS
from mifaces.model.texture_space import rasterize
from mifaces.reflectance.estimate import fit_brdf
from mifaces.model.texture_space import texel_geometry
from mifaces.reflectance.maps.normals import mitsuba_tangent_normals
from mifaces.reflectance import FitOptions

OUT = Path(__file__).resolve().parent / "results"
SFM = Path(__file__).resolve().parents[2] / "shared" / "models" / "sfm_3448" / "sfm_shape_3448.npz"
RUNS = {"true_shapes": ("ground-truth", None), "fitted": ("fitted", None),
        "fitted_normals": ("fitted", {}), "fitted_offsets_only": ("fitted", {"prior_weight": 1e6}),
        "true_shapes_normals": ("ground-truth", {})}


def prepare(work: Path, model_path: Path):
    """The simulated capture and its fitted shapes (made once, in ``work``)."""
    from mifaces import load_model
    from mifaces.shape import fit_shape
    from mifaces.studio import SimulationOptions, simulate

    capture_dir, shapes_dir = work / "sfm_512", work / "sfm_512_shapes"
    if not (capture_dir / "capture.json").is_file():
        simulate(capture_dir, SimulationOptions(face_model=str(model_path)), progress=False)
    capture, model = load_capture(capture_dir), load_model(str(model_path))
    if not (shapes_dir / "shapes.json").is_file():
        fit_shape(capture, model, out=shapes_dir, progress=False)
    return capture, model, capture_dir, shapes_dir


def true_tangent_normals(capture, model, fitted: dict, true: dict, resolution: int) -> np.ndarray:
    """The true normal in each fitted shape's samples frame, averaged over the measurements, (R², 3)."""
    coverage = rasterize(model.uv, model.triangles, (resolution, resolution))
    total = np.zeros((resolution * resolution, 3))
    for name in fitted:
        f = texel_geometry(fitted[name], model.triangles, model.uv, coverage)
        t = texel_geometry(true[name], model.triangles, model.uv, coverage)
        frame = np.stack([f.tangent, f.bitangent, f.normal], axis=1)
        total[f.texel] += np.einsum("mij,mj->mi", frame, t.normal)
    length = np.linalg.norm(total, axis=1, keepdims=True)
    out = np.where(length > 0, total / np.maximum(length, 1e-30), [0.0, 0.0, 1.0])
    return out


def angles(a, b) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def run(capture, model, geometry, options, resolution, truth):
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        estimate = fit_brdf(capture, "cooktorrance", geometry=geometry, face_model=model, progress=False,
                            options=FitOptions(resolution=resolution, normals=options is not None,
                                               normal_options=options, specular_maps=True))
    fit, true = estimate.fits["skin"].params, truth["regions"]["skin"]
    return estimate, {
        "seconds": time.perf_counter() - t0, "samples": estimate.samples,
        "specular_reflectance": list(map(float, fit["specular_reflectance"])), "roughness": float(fit["roughness"]),
        "specular_reflectance_rel": float(np.mean(np.abs(np.asarray(fit["specular_reflectance"]) /
                                                        np.asarray(true["specular_reflectance"]) - 1))),
        "roughness_rel": float(abs(fit["roughness"] / true["roughness"] - 1)),
        "normal_refinement": {k: v for k, v in (estimate.normal_refinement or {}).items() if k != "history"} or None,
        "rounds": len((estimate.normal_refinement or {}).get("history", [])) - 1,
        "specular_map": specular_map_errors(estimate, true)}


def specular_map_errors(estimate, true) -> dict:
    """The per-texel ρ_s map on skin texels with 3 or more samples: its scale k about the region's
    fit (the truth has one ρ_s per region, so k should stay near 1) and its error against the truth."""
    skin = (estimate.region_map == REGIONS["skin"]) & (estimate.albedo.samples >= 3)
    k = estimate.specular.scale[skin]
    texel = estimate.specular.specular[skin].mean(axis=1) / np.mean(true["specular_reflectance"])
    return {"texels": int(skin.sum()), "scale_median_abs_deviation": float(np.median(np.abs(k - 1))),
            "scale_p5_p95": [float(np.percentile(k, 5)), float(np.percentile(k, 95))],
            "texel_rho_s_rel_error_mean": float(np.mean(np.abs(texel - 1))),
            "texel_rho_s_rel_error_median": float(np.median(np.abs(texel - 1)))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, default=Path("out/normals_faces"))
    parser.add_argument("--model", type=Path, default=SFM, help="Surrey Face Model npz")
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--results", type=Path, default=OUT)
    args = parser.parse_args(argv)
    capture, model, capture_dir, shapes_dir = prepare(args.work, args.model)
    ground_truth = read_ground_truth(capture_dir)
    _, fitted = load_geometry(capture, str(shapes_dir), model)
    _, true = load_geometry(capture, "ground-truth", model)
    r = args.resolution
    true_ts = true_tangent_normals(capture, model, fitted, true, r).reshape(r, r, 3)
    first = next(m.name for m in capture.measurements if m.name in fitted)
    true_mitsuba = mitsuba_tangent_normals(true_ts, model, fitted[first]).reshape(-1, 3)
    result = {"data": "SIMULATED", "capture": str(capture_dir), "resolution": r, "runs": {},
              "command": "python validation/normals_faces.py " + " ".join(argv if argv is not None else sys.argv[1:])}
    maps = {}
    for label, (geometry, options) in RUNS.items():
        estimate, row = run(capture, model, str(shapes_dir) if geometry == "fitted" else geometry, options, r,
                            ground_truth.brdf)
        if geometry == "fitted":
            skin = (estimate.region_map.ravel() == REGIONS["skin"]) & (estimate.albedo.samples.ravel() >= 3)
            used = (np.tile([0.0, 0.0, 1.0], (r * r, 1)) if estimate.normals is None
                    else estimate.normals.reshape(-1, 3).astype(np.float64))
            row["skin_normal_error_deg"] = float(angles(used[skin], true_mitsuba[skin]).mean())
            maps[label] = np.where(skin, angles(used, true_mitsuba), np.nan).reshape(r, r)
        result["runs"][label] = row
        print(f"{label:22s} rho_s {100 * row['specular_reflectance_rel']:5.1f} %  roughness "
              f"{100 * row['roughness_rel']:5.1f} %  normals {row.get('skin_normal_error_deg', float('nan')):.2f} deg"
              f"  {row['seconds']:.0f} s; texel rho_s map median error "
              f"{100 * row['specular_map']['texel_rho_s_rel_error_median']:.1f} %", flush=True)
    write_json(args.results / "normals_faces.json", result)
    figure(result, maps, args.results / "normals_faces.png")
    return 0


def figure(result: dict, maps: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = result["runs"]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    labels = list(runs)
    x = np.arange(len(labels))
    axes[0].bar(x - 0.2, [100 * runs[k]["specular_reflectance_rel"] for k in labels], 0.4, label="ρ_s")
    axes[0].bar(x + 0.2, [100 * runs[k]["roughness_rel"] for k in labels], 0.4, label="roughness")
    axes[0].axhline(10, color="C0", ls=":", lw=1)
    axes[0].axhline(3, color="C1", ls=":", lw=1)
    axes[0].set_xticks(x, [k.replace("_", "\n") for k in labels], fontsize=8)
    axes[0].set_ylabel("skin relative error (%)")
    axes[0].legend()
    axes[0].set_title("skin gloss error (targets dotted)")
    for ax, key in zip(axes[1:], ("fitted", "fitted_normals")):
        image = ax.imshow(maps[key], vmin=0, vmax=8, cmap="magma")
        ax.set_title(f"{key}: normal error, mean {runs[key]['skin_normal_error_deg']:.2f}°")
        ax.axis("off")
        fig.colorbar(image, ax=ax, fraction=0.046, label="degrees")
    fig.suptitle("SIMULATED Surrey capture, fitted shapes: per-texel normals (Cook-Torrance, "
                 f"{result['resolution']}² texture)")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


if __name__ == "__main__":
    raise SystemExit(main())
