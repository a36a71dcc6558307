"""How far the built-in model's span reaches real faces: its landmarks fitted to Surrey faces.

The Surrey Face Model (``../shared/models/sfm_3448``) is a PCA of real 3D
scans, made independently of the built-in model (the ICT Face Model Light).
Random Surrey faces (coefficients from its prior) stand in for real people.
For each, the built-in model is fitted to the face's iBUG landmarks (those
both models define: 50 of 68, the Surrey model leaves the jaw contour out
but the chin): a rigid alignment (rotation and translation, no scale)
alternating with regularised least squares for the identity coefficients,

    min_a  sum_l || R (mean_l + B_l (sigma * a)) + t - target_l ||^2  +  w ||a||^2,   w = 1 (mm^2),

twenty rounds. Reported: the mean landmark residual (mm) and the largest
coefficient (standard deviations), per face and in summary, for a range of
mode counts.

The number of modes the shape fit uses by default
(``mifaces.model.builtin.FIT_SHAPE_MODES``) is chosen here on *training*
faces (another seed), as the fewest modes whose mean residual is within
0.1 mm of all 100; the *test* faces, on which the figures are reported,
played no part in it. Usage::

    python validation/model_span.py [--sfm ../shared/models/sfm_3448/sfm_shape_3448.npz]

Writes ``validation/results/model_span.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip
import numpy as np

from mifaces.model import load_model
from mifaces.model.builtin import FIT_SHAPE_MODES
from mifaces.shape_errors import rigid_alignment

HERE = Path(__file__).resolve().parent
SFM = HERE.parent.parent / "shared" / "models" / "sfm_3448" / "sfm_shape_3448.npz"
MODES = (10, 20, 30, 40, 50, 60, 80, 100)
TEST_SEED, TRAIN_SEED = 2024, 7
PRIOR_WEIGHT = 1.0


def fit_landmarks(model, vertices: list[int], target: np.ndarray, modes: int, rounds: int = 20):
    """Coefficients (modes,), the residual per landmark (mm) of the model fitted to ``target``."""
    mean = model.shape_mean[vertices].astype(np.float64)
    basis = model.shape_basis.reshape(-1, 3, model.shape_dim)[vertices][:, :, :modes].astype(np.float64)
    basis = basis * np.sqrt(model.shape_variance[:modes])
    a = np.zeros(modes)
    for _ in range(rounds):
        shape = mean + basis @ a
        rotation, translation = rigid_alignment(shape, target)
        local = (target - translation) @ rotation  # the target in the model's frame
        design = basis.reshape(-1, modes)
        a = np.linalg.solve(design.T @ design + PRIOR_WEIGHT * np.eye(modes), design.T @ (local - mean).ravel())
    shape = mean + basis @ a
    rotation, translation = rigid_alignment(shape, target)
    residual = np.linalg.norm(shape @ rotation.T + translation - target, axis=1)
    return a, residual


def evaluate(model, sfm, seed: int, faces: int, modes: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    common = sorted(set(model.ibug_landmarks) & set(sfm.ibug_landmarks))
    ours = [model.ibug_landmarks[i] for i in common]
    theirs = [sfm.ibug_landmarks[i] for i in common]
    rows = []
    for _ in range(faces):
        target = sfm.shape(rng.standard_normal(sfm.shape_dim))[theirs].astype(np.float64)
        a, residual = fit_landmarks(model, ours, target, modes)
        inner = [k for k, i in enumerate(common) if i >= 18]
        rows.append({"mean_residual_mm": float(residual.mean()), "inner_mean_residual_mm": float(residual[inner].mean()),
                     "max_abs_coefficient_sd": float(np.abs(a).max())})
    return rows


def summary(rows: list[dict]) -> dict:
    r = np.array([x["mean_residual_mm"] for x in rows])
    c = np.array([x["max_abs_coefficient_sd"] for x in rows])
    inner = np.array([x["inner_mean_residual_mm"] for x in rows])
    return {"mean_residual_mm": float(r.mean()), "worst_face_residual_mm": float(r.max()),
            "inner_mean_residual_mm": float(inner.mean()), "max_abs_coefficient_sd": float(c.max()),
            "mean_max_abs_coefficient_sd": float(c.mean())}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sfm", type=Path, default=SFM)
    parser.add_argument("--faces", type=int, default=20)
    parser.add_argument("--out", type=Path, default=HERE / "results" / "model_span.json")
    args = parser.parse_args(argv)
    model, sfm = load_model("builtin"), load_model(args.sfm)
    result = {"command": "python validation/model_span.py", "model": model.name, "model_modes": model.shape_dim,
              "reference": str(args.sfm.name), "faces": args.faces, "prior_weight_mm2": PRIOR_WEIGHT,
              "landmarks": len(set(model.ibug_landmarks) & set(sfm.ibug_landmarks)),
              "train_seed": TRAIN_SEED, "test_seed": TEST_SEED, "train": {}, "test": {}}
    for k in MODES:
        result["train"][str(k)] = summary(evaluate(model, sfm, TRAIN_SEED, args.faces, k))
        rows = evaluate(model, sfm, TEST_SEED, args.faces, k)
        result["test"][str(k)] = dict(summary(rows), faces=rows)
        print(f"{k:3d} modes: train {result['train'][str(k)]['mean_residual_mm']:.2f} mm; test "
              f"{result['test'][str(k)]['mean_residual_mm']:.2f} mm mean residual, coefficients up to "
              f"{result['test'][str(k)]['max_abs_coefficient_sd']:.2f} sd")
    full = result["train"][str(MODES[-1])]["mean_residual_mm"]
    chosen = min(k for k in MODES if result["train"][str(k)]["mean_residual_mm"] <= full + 0.1)
    result["chosen_on_train"] = chosen
    result["fit_shape_modes"] = FIT_SHAPE_MODES
    print(f"fewest modes within 0.1 mm of all {MODES[-1]} on the training faces: {chosen} "
          f"(the shape fit's default: {FIT_SHAPE_MODES})")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
