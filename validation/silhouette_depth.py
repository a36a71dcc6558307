"""Whether the head's outline could pin each photograph's depth (SIMULATED).

The diffuse-light companion of each simulated photograph shows the whole head against a bright
background, so its outline is a candidate for what the feature points cannot give: each
photograph's depth to 0.08 % (1 mm at 1.2 m). For each seed this simulates the default capture,
fits its faces with the defaults (:func:`mifaces.shape.fit_shape`) and, for every photograph,
moves the fitted face and the true face along the camera's ray through the face's centre by
``dz`` (a depth change with the size held: the outline grows or shrinks in the image) and counts
the pixels where the face's coverage (the share of 4x4 sub-pixel rays that hit it) and the
photograph's foreground (darker than halfway between the background and the skin) disagree, over
the rows above the middle of the nose (:data:`ROWS_PERCENTILE`: the jaw, neck and shoulders are
left out). The ``dz`` of least disagreement is what
an outline term would move the face by; the true face's should be 0, the fitted face's minus its
depth error (``depth_mm``, positive: farther than the truth).

Nothing is chosen on these runs: they measure a cue, they tune nothing.

    python validation/silhouette_depth.py [--seeds 1 2] [--work DIR]

Writes ``validation/results/silhouette_depth.json`` and ``silhouette_depth.png`` (the outlines of
the first seed's first photograph).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import mifaces  # first: libLLVM  # isort: skip

import numpy as np

from mifaces.io.atomic import save_figure, write_json
from mifaces.render.face_pixels import face_pixels
from mifaces.render import FaceScene
from mifaces.validation.shape_errors import capture_shape_errors

from shape_depth import fitted_shapes, simulated_default  # noqa: E402  (the captures of validation/shape_depth.py)

RESULTS = Path(__file__).resolve().parent / "results"
#: Coverage samples per pixel side.
SUPERSAMPLE = 4
#: Depth offsets scanned (mm) for the fitted face and for the true face.
FIT_OFFSETS = np.arange(-24.0, 24.01, 3.0)
TRUE_OFFSETS = np.arange(-4.0, 4.01, 1.0)
#: The rows scored: above this percentile of the fitted face's projected vertices' rows (about row 290 of
#: 512, between the eyes and the nose's tip; the jaw, neck and shoulders are left out).
ROWS_PERCENTILE = 60


def coverage(face, vertices, camera) -> np.ndarray:
    """Fraction of each pixel of ``camera`` that the face ``vertices`` cover: the share of its
    SUPERSAMPLE² sub-pixel centres whose rays hit the face (:func:`mifaces.render.face_pixels.face_pixels`
    on a camera SUPERSAMPLE times finer)."""
    s = SUPERSAMPLE
    hit = face_pixels(FaceScene(face, np.asarray(vertices, np.float32)), camera.scaled(s), spp=None)
    return hit.reshape(camera.height, s, camera.width, s).mean(axis=(1, 3))


def least(offsets, disagreement) -> tuple[float, bool]:
    """The offset of least disagreement, refined by a parabola through its neighbours, and whether it
    lies at an end of the scan (then the end itself: the least may lie beyond)."""
    i = int(np.argmin(disagreement))
    if i in (0, len(offsets) - 1):
        return float(offsets[i]), True
    y0, y1, y2 = disagreement[i - 1:i + 2]
    curvature = y0 - 2 * y1 + y2
    step = offsets[1] - offsets[0]
    return float(offsets[i] + (0.5 * (y0 - y2) / curvature * step if curvature > 0 else 0.0)), False


def scan(face, vertices, camera, foreground, rows, offsets) -> np.ndarray:
    centre = vertices.mean(axis=0)
    ray = (centre - camera.position) / np.linalg.norm(centre - camera.position)
    return np.array([np.abs(coverage(face, vertices + dz * ray, camera) - foreground)[:rows].sum()
                     for dz in offsets])


def photograph_row(face, measurement, camera, fitted, true, error) -> tuple[dict, dict]:
    grey = measurement.diffuse.pixels.mean(axis=-1)
    border = np.concatenate([grey[0], grey[-1], grey[:, 0], grey[:, -1]])
    background = float(np.median(border))
    true_coverage = coverage(face, true, camera)
    skin = float(np.median(grey[true_coverage > 0.99]))
    foreground = (grey < 0.5 * (background + skin)).astype(float)
    rows = int(np.percentile(camera.project(fitted)[:, 1], ROWS_PERCENTILE))
    fit_scan = scan(face, fitted, camera, foreground, rows, FIT_OFFSETS)
    true_scan = scan(face, true, camera, foreground, rows, TRUE_OFFSETS)
    (fitted_dz, fitted_end), (true_dz, true_end) = least(FIT_OFFSETS, fit_scan), least(TRUE_OFFSETS, true_scan)
    row = {"depth_mm": error["depth_mm"], "world_mm": error["world_mm"],
           "fitted_best_dz_mm": fitted_dz, "true_best_dz_mm": true_dz,
           "fitted_at_scan_end": fitted_end, "true_at_scan_end": true_end,
           "fitted_disagreement_px": float(fit_scan[len(FIT_OFFSETS) // 2]),
           "fitted_least_disagreement_px": float(fit_scan.min()),
           "true_disagreement_px": float(true_scan[len(TRUE_OFFSETS) // 2]),
           "rows": rows, "background": background, "skin": skin}
    picture = {"foreground": foreground, "true": true_coverage,
               "fitted": coverage(face, fitted, camera)}
    return row, picture


def seed_run(seed: int, work: Path) -> tuple[dict, dict]:
    capture, face, truth = simulated_default(seed, work)
    _, shapes, seconds = fitted_shapes(capture, face)
    errors = capture_shape_errors(face, shapes, truth, capture.camera)
    out, first = {"seed": seed, "fit_seconds": seconds, "photographs": {}}, None
    for m in capture.measurements:
        if m.name not in shapes or m.diffuse is None:
            continue
        row, picture = photograph_row(face, m, capture.camera, shapes[m.name], truth[m.name], errors[m.name])
        out["photographs"][m.name] = row
        first = first or dict(picture, name=m.name)
        print(f"seed {seed} {m.name}: depth error {row['depth_mm']:+.2f} mm; outline's dz: fitted face "
              f"{row['fitted_best_dz_mm']:+.1f} mm, true face {row['true_best_dz_mm']:+.2f} mm; disagreement "
              f"{row['fitted_disagreement_px']:.0f} px (true face {row['true_disagreement_px']:.0f})", flush=True)
    return out, first


def figure(picture: dict, seed: int, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 6))
    ax.imshow(np.stack([picture["foreground"], picture["fitted"], picture["true"]], axis=-1))
    ax.set_title(f"seed {seed}, {picture['name']}: red the photograph's foreground, green the fitted face,\n"
                 "blue the true face (white: all three; magenta: photograph and truth, not the fit)", fontsize=8)
    ax.set_axis_off()
    save_figure(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--work", type=Path, default=Path("out/silhouette_depth"))
    args = parser.parse_args(argv)
    mifaces.set_variant("llvm_ad_rgb")
    runs, picture = [], None
    for seed in args.seeds:
        run, first = seed_run(seed, args.work)
        runs.append(run)
        picture = picture or (first and dict(first, seed=seed))
    rows = [r for run in runs for r in run["photographs"].values()]
    summary = {
        "mean_abs_depth_mm": float(np.mean([abs(r["depth_mm"]) for r in rows])),
        "mean_abs_true_best_dz_mm": float(np.mean([abs(r["true_best_dz_mm"]) for r in rows])),
        "mean_fitted_best_dz_mm": float(np.mean([r["fitted_best_dz_mm"] for r in rows])),
        "mean_abs_fitted_dz_error_mm": float(np.mean([abs(r["fitted_best_dz_mm"] + r["depth_mm"]) for r in rows])),
        "fitted_at_scan_end": int(sum(r["fitted_at_scan_end"] for r in rows)),
        "true_at_scan_end": int(sum(r["true_at_scan_end"] for r in rows)), "photographs": len(rows),
        "mean_fitted_disagreement_px": float(np.mean([r["fitted_disagreement_px"] for r in rows])),
        "mean_true_disagreement_px": float(np.mean([r["true_disagreement_px"] for r in rows])),
    }
    write_json(RESULTS / "silhouette_depth.json", {
        "label": "SIMULATED", "command": "python validation/silhouette_depth.py " + " ".join(argv or sys.argv[1:]),
        "seeds": args.seeds, "supersample": SUPERSAMPLE, "fit_offsets_mm": FIT_OFFSETS.tolist(),
        "true_offsets_mm": TRUE_OFFSETS.tolist(), "summary": summary, "runs": runs})
    if picture:
        figure(picture, picture["seed"], RESULTS / "silhouette_depth.png")
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
