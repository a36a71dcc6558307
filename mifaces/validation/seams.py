"""Region outlines in a fitted render: the step of the fitted face over the true one across each
border between two regions (:func:`border_steps`), and the borders where it exceeds the noise
(:func:`seams`). On a face whose regions all share one BRDF, no region may show its outline
(issue 50; ``tests/test_region_blend.py``, ``validation/region_seams.py``)."""

from __future__ import annotations

import json

import numpy as np

from ..capture import load_capture
from ..capture.ground_truth import ground_truth_folder
from ..io.image_files import read_exr
from ..render import FaceScene
from ..shape.io import load_geometry
from ..studio.truth import default_brdf
from ..model.regions import REGIONS, texel_regions_of_mesh
from ..render.face_pixels import face_pixels

#: A step counts as a seam beyond three standard errors plus this (log radiance: 1 %, below what
#: the eye sees).
ALLOWANCE = 0.01
#: Fewer neighbouring pixel pairs than this along a border: no verdict on it.
MIN_PAIRS = 50


def one_brdf(model: str = "cooktorrance") -> dict:
    """Overrides for :func:`mifaces.simulate` (``brdf_params``) that give every region the skin's
    glossy parameters of the default truth of ``model``: one BRDF everywhere (the albedo map keeps
    its dark eyebrows and stubble)."""
    skin = default_brdf(model)["regions"]["skin"]
    return {"model": model, "regions": {r: dict(skin) for r in REGIONS if r != "background"}}


def seam_renders(capture_dir, estimate, brdf: dict | None = None, spp: int = 64, seed: int = 1):
    """The first photograph of the simulated capture ``capture_dir`` rendered from ``estimate``
    (a :class:`~mifaces.reflectance.result.BRDFEstimate` on the true shapes; ``brdf``: another
    document in its place) and from the truth, at one seed, and each pixel's region
    (:func:`pixel_regions`): (fitted, true, labels)."""
    capture = load_capture(capture_dir)
    model, shapes = load_geometry(capture)
    first = capture.measurements[0]
    scene = FaceScene(model, shapes[first.name])
    light = capture.light(first.light)
    truth = ground_truth_folder(capture_dir)
    true = scene.render(json.loads((truth / "brdf.json").read_text()), read_exr(truth / "albedo.exr"),
                        capture.camera, light, spp=spp, seed=seed)
    fitted = scene.render(estimate.to_json() if brdf is None else brdf, estimate.albedo.albedo, capture.camera,
                          light, spp=spp, seed=seed, normals=estimate.normal_texture())
    return fitted, true, pixel_regions(scene, capture.camera, model)


def pixel_regions(scene, camera, face_model) -> np.ndarray:
    """(H, W) region label of each pixel of ``camera``'s image of ``scene`` (a
    :class:`~mifaces.render.FaceScene` of ``face_model``): the label where the ray through its
    centre meets the face, 0 off the face."""
    labels = texel_regions_of_mesh(face_model.region_map, face_model.uv, face_model.triangles, 1024)
    return face_pixels(scene, camera, spp=None, region_map=labels)


def border_steps(image: np.ndarray, reference: np.ndarray, labels: np.ndarray, minimum: int = MIN_PAIRS) -> dict:
    """The step of log(image / reference) across each border between two regions (pixel ``labels``,
    0 off the face): (first label, second label) -> (mean step from the first region's pixel to the
    second's over the pairs of neighbouring pixels that straddle the border, its standard error, the
    number of pairs), for the borders with at least ``minimum`` pairs. A face whose reflectance each
    region's fit got equally right has no step there; a region fitted too glossy or too dark shows
    one all along its border."""
    lum_image, lum_ref = np.asarray(image).mean(axis=2), np.asarray(reference).mean(axis=2)
    ok = (lum_image > 1e-3) & (lum_ref > 1e-3) & (labels > 0)
    ratio = np.log(np.where(ok, lum_image, 1.0)) - np.log(np.where(ok, lum_ref, 1.0))
    firsts, seconds, steps = [], [], []
    for a, b in (((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
                 ((slice(None), slice(None, -1)), (slice(None), slice(1, None)))):
        across = ok[a] & ok[b] & (labels[a] != labels[b])
        first, second, step = labels[a][across], labels[b][across], (ratio[b] - ratio[a])[across]
        flip = first > second
        firsts.append(np.where(flip, second, first))
        seconds.append(np.where(flip, first, second))
        steps.append(np.where(flip, -step, step))
    firsts, seconds, steps = np.concatenate(firsts), np.concatenate(seconds), np.concatenate(steps)
    out = {}
    for lo, hi in sorted(set(zip(firsts.tolist(), seconds.tolist()))):
        s = steps[(firsts == lo) & (seconds == hi)]
        if len(s) >= minimum:
            out[(lo, hi)] = (float(s.mean()), float(s.std(ddof=1) / np.sqrt(len(s))), int(len(s)))
    return out


def border_name(pair: tuple[int, int]) -> str:
    """``"skin/eyebrows"`` for a pair of region labels."""
    names = {v: k for k, v in REGIONS.items()}
    return "/".join(names[label] for label in pair)


def seams(steps: dict, allowance: float = ALLOWANCE) -> dict[str, float]:
    """The borders of :func:`border_steps` whose step exceeds three standard errors (the Monte Carlo
    noise and the texture's) plus ``allowance``: border name -> step."""
    return {border_name(pair): round(mean, 4) for pair, (mean, se, _) in steps.items()
            if abs(mean) > 3 * se + allowance}


__all__ = ["ALLOWANCE", "MIN_PAIRS", "border_name", "border_steps", "one_brdf", "pixel_regions", "seam_renders",
           "seams"]
