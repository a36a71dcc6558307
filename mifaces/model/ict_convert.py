"""Convert the ICT Face Model Light into the built-in model file that ships with mifaces.

Run once by a maintainer; the repository commits the result
(``mifaces/model/data/ict_face.npz``) and the MIT notice beside it::

    python -m mifaces.model.ict_convert ../shared/models/ict_facekit

What it keeps, and why (``docs/model.md`` has the whole account):

* **Parts.** The face, the back of the head and the neck, the eye sockets
  and the eyeballs (sclera and iris): what fitting and rendering use. The
  mouth socket, gums, tongue, teeth, lacrimal fluid, eye blend and
  occlusion shells and the lashes are left out (nothing here renders an
  open mouth or lashes).
* **Units and frame.** Centimetres become millimetres; the frame is
  already the project's (y up, the face looking along +z).
* **Texture space.** The toolkit's UVs are per face corner and UDIM-like
  (face in tile 0, back of the head in tile 1, each eye part in its own
  unit tile). Here every part gets its own rectangle of one unit square
  (:data:`ATLAS`), ``v`` flipped to Mitsuba's top-row-first convention, and
  a vertex is split wherever its corners have different texture
  coordinates (the seams), so that the model keeps one uv per vertex.
  Copies of a vertex share its basis rows and move together.
* **Identity.** The 100 identity modes, restricted to the kept vertices,
  are re-diagonalised (``M = U S Vᵀ``): the basis ``U`` is orthonormal on
  the kept mesh and the variances are ``S²``. Faces ``M c`` with
  ``c ~ N(0, I)`` have exactly the distribution of ``U (S a)`` with
  ``a ~ N(0, I)``, so the span and the prior are the toolkit's; the
  coefficients are a rotation of the toolkit's.
* **Expressions.** :data:`EXPRESSIONS`, a subset of the 53 ARKit-style
  blend shapes: subtle brow, eye, cheek and mouth movements of a sitter
  (no open jaw, no blink).
* **Storage.** The basis and the expressions as int16 with one scale per
  column, the mean as float32, compressed; :func:`precision` measures what
  that loses (stored in the file's metadata).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import scipy.ndimage as ndi

from .regions import REGIONS, _fill_polygon, region_map_from_landmarks
from .texture_space import rasterize

#: Where the converted model lives inside the package.
DATA_DIR = Path(__file__).parent / "data"
MODEL_FILE = DATA_DIR / "ict_face.npz"
LICENSE_FILE = DATA_DIR / "LICENSE-ICT-FaceKit.txt"
#: Format of the packaged file (bump when the layout changes).
FORMAT = 1
#: The toolkit's source (its README in ``../shared/models/ict_facekit``).
SOURCE = {"name": "ICT Face Model Light (ICT-FaceKit)", "url": "github.com/ICT-VGL/ICT-FaceKit",
          "commit": "da5f95a607f5e6b37755b38d3385d7f2853732e5", "licence": "MIT",
          "citation": "Li, Bladin, Zhao et al., Learning Formation of Physically-Based Face Attributes, "
                      "CVPR 2020"}
#: Millimetres per unit of the toolkit (centimetres).
MM = 10.0
#: Kept material -> (atlas rectangle u0, v0, size; toolkit tile u0) and region label.
ATLAS = {
    "M_Face": ((0.0, 0.0, 0.8), 0, "skin"),
    "M_BackHead": ((0.8, 0.0, 0.2), 1, "hair"),
    "M_ScleraRight": ((0.8, 0.2, 0.1), 0, "eyes"),
    "M_IrisRight": ((0.9, 0.2, 0.1), 0, "eyes"),
    "M_ScleraLeft": ((0.8, 0.3, 0.1), 0, "eyes"),
    "M_IrisLeft": ((0.9, 0.3, 0.1), 0, "eyes"),
}
#: Parts whose texture space folds over itself (the iris's inner rim turns back into the eye): their
#: faces of the minority orientation move to a rectangle of their own (u0, v0, size).
FOLDS = {"M_IrisRight": (0.8, 0.4, 0.1), "M_IrisLeft": (0.9, 0.4, 0.1)}
#: Vertices of the mouth socket (0-based, inclusive): part of M_BackHead, left out.
MOUTH_SOCKET = (11248, 13293)
#: Expression blend shapes kept (ARKit names).
EXPRESSIONS = ("browDown_L", "browDown_R", "browInnerUp_L", "browInnerUp_R", "browOuterUp_L", "browOuterUp_R",
               "cheekSquint_L", "cheekSquint_R", "eyeSquint_L", "eyeSquint_R", "mouthSmile_L", "mouthSmile_R",
               "mouthFrown_L", "mouthFrown_R", "mouthPucker", "noseSneer_L")
#: Jaw-line substitutes for iBUG 1-8 and 10-17 on a turned head (the toolkit's README), per side.
CONTOUR_SUBSTITUTES = {"right": (1278, 1272, 12, 1834, 243, 781, 2199, 1447),
                       "left": (3661, 4390, 3022, 2484, 4036, 2253, 3490, 3496)}
#: iBUG points outlining the beard: the jaw from below one ear lobe to the other, then the nose base.
BEARD_OUTLINE = (4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 36, 35, 34, 33, 32)
#: Texels by which each island's labels reach into the background around it, so that a lookup
#: at a vertex on an island's border (nearest texel) finds its island's label.
REGION_MAP_MARGIN = 4
#: The 68 iBUG landmark vertices (the toolkit's indices): chosen by ``tools/ict_landmarks.py`` where
#: dlib's detector puts each point on renders of the model (capped RMS over 30 renders of 6 faces in
#: 5 poses: 5.35 px with the toolkit's own table, 3.37 px with this one, at 1.7 px/mm); None would
#: take the toolkit's table.
LANDMARKS = (1794, 1196, 1783, 365, 747, 765, 1675, 2195, 2191, 4386, 3930, 3006, 2988, 2616, 3986, 3415, 8456,
             268, 436, 1693, 2056, 1616, 3825, 4259, 2680, 2677, 2509, 977, 4522, 4942, 4857, 4584, 2088, 1147,
             4282, 5049, 1546, 1576, 616, 630, 591, 1512, 3129, 2857, 3790, 3760, 3726, 2813, 5732, 5692, 6029,
             5524, 6547, 6197, 6495, 6357, 6508, 5518, 6004, 5870, 5777, 6009, 5517, 6513, 6690, 6512, 5515, 6008)
#: Size of the region map (texels).
REGION_MAP_SIZE = 1024


def source_vertices(path: Path = MODEL_FILE) -> np.ndarray:
    """The toolkit's vertex index of each vertex of the packaged model (seam copies repeat it)."""
    with np.load(path) as d:
        return d["toolkit_vertex"][d["source_row"]]


def _quantise(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """int16 columns and their scales: ``matrix ≈ q * scale``."""
    scale = np.abs(matrix).max(axis=0) / 32767.0
    scale = np.where(scale > 0, scale, 1.0)
    return np.round(matrix / scale).astype(np.int16), scale.astype(np.float64)


def _triangles(quads: np.ndarray) -> np.ndarray:
    """Split quads (and -1 padded triangles) into triangles (a, b, c), (a, c, d); (F, 4) -> (T, 3)
    indices into the face-corner array ``F * 4``."""
    corner = np.arange(quads.size).reshape(quads.shape)
    first = corner[:, [0, 1, 2]]
    quad = quads[:, 3] >= 0
    second = corner[quad][:, [0, 2, 3]]
    return np.concatenate([first, second])


def _unfold(uv: np.ndarray, valid: np.ndarray, rect: tuple[float, float, float]) -> np.ndarray:
    """Move the faces of a part whose texture-space orientation is the minority's (a fold) to
    ``rect``, keeping their layout: (F, 4, 2) corner uvs in, the same out."""
    t = uv[:, :3]
    area = (t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1]) - (t[:, 2, 0] - t[:, 0, 0]) * (t[:, 1, 1] - t[:, 0, 1])
    folded = np.sign(area) != np.sign(np.sum(np.sign(area)))
    if not folded.any():
        return uv
    out = uv.copy()
    corners = uv[folded][valid[folded]]
    low, span = corners.min(axis=0), max(float(np.ptp(corners, axis=0).max()), 1e-12)
    u0, v0, size = rect
    out[folded] = np.array([u0, v0]) + size * (uv[folded] - low) / span
    return out


def _region_map(uv: np.ndarray, triangles: np.ndarray, triangle_label: np.ndarray, landmarks: dict,
                face_triangles: np.ndarray) -> np.ndarray:
    """The a-priori region map: each part's label, the back of the head's scalp as hair and its
    neck as skin, and the features (lips, eyebrows, nostrils) outlined by the landmarks on the face."""
    size = (REGION_MAP_SIZE, REGION_MAP_SIZE)
    raster = rasterize(uv, triangles, size)
    image = np.zeros(size, np.uint8)
    covered = raster.covered
    image[covered] = triangle_label[raster.triangle[covered]]
    features = region_map_from_landmarks(uv, face_triangles, landmarks, size)
    beard = [landmarks[i] for i in BEARD_OUTLINE]
    _fill_polygon(image, REGIONS["beard"], uv[beard], image == REGIONS["skin"])
    for name in ("lips", "eyebrows", "nostrils"):
        image[features == REGIONS[name]] = REGIONS[name]
    return image


def convert(source: Path) -> dict[str, np.ndarray]:
    """The arrays of the packaged model, from the toolkit's ``ict_facekit.npz`` and
    ``vertex_indices.json`` in ``source``."""
    with np.load(source / "ict_facekit.npz") as d:
        raw = {k: d[k] for k in d.files}
    indices = json.loads((source / "vertex_indices.json").read_text())
    materials = [str(m) for m in raw["material_names"]]
    quads, quad_uv, material = raw["face_vertices"], raw["face_uvs"], raw["face_material"]

    keep_face = np.zeros(len(quads), bool)
    for name in ATLAS:
        keep_face |= material == materials.index(name)
    in_socket = ((quads >= MOUTH_SOCKET[0]) & (quads <= MOUTH_SOCKET[1])).any(axis=1)
    keep_face &= ~in_socket
    quads, quad_uv, material = quads[keep_face], quad_uv[keep_face], material[keep_face]

    # Atlas texture coordinates per corner; v flipped to Mitsuba's convention.
    corner_uv = np.zeros(quads.shape + (2,))
    corner_label = np.zeros(len(quads), np.uint8)
    for name, ((u0, v0, size), tile, region) in ATLAS.items():
        sel = material == materials.index(name)
        uv = raw["uv"][quad_uv[sel]].astype(np.float64)
        local = np.stack([uv[..., 0] - tile, 1.0 - uv[..., 1]], axis=-1)
        corner_uv[sel] = np.array([u0, v0]) + size * np.clip(local, 0.0, 1.0)
        corner_label[sel] = REGIONS[region]
        if name in FOLDS:
            corner_uv[sel] = _unfold(corner_uv[sel], quads[sel] >= 0, FOLDS[name])
    # One vertex per (toolkit vertex, texture coordinate) pair.
    flat_vertex = quads.ravel()
    flat_uv = corner_uv.reshape(-1, 2)
    valid = flat_vertex >= 0
    key = np.stack([flat_vertex[valid].astype(np.float64), np.round(flat_uv[valid, 0] * 2 ** 22),
                    np.round(flat_uv[valid, 1] * 2 ** 22)], axis=1)
    unique_key, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    corner_vertex = np.full(flat_vertex.shape, -1, np.int64)
    corner_vertex[valid] = inverse.ravel()
    source_vertex = unique_key[:, 0].astype(np.int64)  # toolkit vertex of each new vertex
    vertex_uv = flat_uv[valid][first]
    triangles = corner_vertex[_triangles(quads)]
    triangle_part = np.concatenate([corner_label, corner_label[quads[:, 3] >= 0]])

    # The toolkit vertices kept, and each new vertex's row among them.
    kept, source_row = np.unique(source_vertex, return_inverse=True)
    neutral = raw["neutral_vertices"][kept].astype(np.float64) * MM
    modes = raw["identity_modes"][:, kept].astype(np.float64) * MM  # (100, K, 3)
    # Re-diagonalise on the split mesh (rows weighted as the expanded basis counts them).
    expanded = modes[:, source_row].reshape(len(modes), -1).T  # (3N, 100)
    u, s, _ = np.linalg.svd(expanded, full_matrices=False)
    u *= np.sign(u[np.argmax(np.abs(u), axis=0), np.arange(u.shape[1])])  # deterministic signs
    first_row = np.unique(source_row, return_index=True)[1]
    basis_kept = u.reshape(len(source_row), 3, -1)[first_row].reshape(3 * len(kept), -1)
    names = [str(n) for n in raw["expression_names"]]
    expressions = np.stack([raw["expression_modes"][names.index(e)][kept].ravel() * MM for e in EXPRESSIONS], 1)

    # Triangles are counter-clockwise seen from outside? Check on the face part and flip if not.
    v = neutral[source_row]
    n = np.cross(v[triangles[:, 1]] - v[triangles[:, 0]], v[triangles[:, 2]] - v[triangles[:, 0]])
    face_tri = triangle_part == REGIONS["skin"]
    outward = np.sum(n[face_tri] * (v[triangles[face_tri]].mean(axis=1) - v.mean(axis=0)), axis=1)
    if np.median(outward) < 0:
        triangles = triangles[:, [0, 2, 1]]

    first_copy = {int(k): int(np.flatnonzero(source_vertex == k)[0]) for k in
                  set(LANDMARKS or ()) | set(indices["idx_to_landmark_verts"])
                  | {k for side in CONTOUR_SUBSTITUTES.values() for k in side}}
    landmarks = np.array([(i + 1, first_copy[k]) for i, k in enumerate(LANDMARKS or indices["idx_to_landmark_verts"])],
                         np.int32)
    # the regions follow the toolkit's own (anatomical) landmarks: the detector's points are fitted
    # to renders painted from these regions, so the regions must not move with them
    anatomical = {i + 1: first_copy[k] for i, k in enumerate(indices["idx_to_landmark_verts"])}
    region_map = _region_map(vertex_uv, triangles, triangle_part, anatomical,
                             triangles[face_tri])
    region_map = _neck_and_scalp(region_map, vertex_uv, triangles, v, triangle_part)
    region_map = _dilate(region_map, REGION_MAP_MARGIN)

    basis_q, basis_scale = _quantise(basis_kept)
    expr_q, expr_scale = _quantise(expressions)
    metadata = dict(SOURCE, units="mm", parts=list(ATLAS), expressions=list(EXPRESSIONS),
                    contour_substitutes={side: [first_copy[k] for k in ks] for side, ks in CONTOUR_SUBSTITUTES.items()},
                    identity="the toolkit's 100 identity modes restricted to the kept vertices, re-diagonalised "
                             "(SVD): an orthonormal basis ordered by variance, spanning the same space")
    arrays = {"format": np.int32(FORMAT), "neutral": neutral.astype(np.float32), "source_row": source_row.astype(np.int32),
              "toolkit_vertex": kept.astype(np.int32),
              "uv": vertex_uv.astype(np.float32), "triangles": triangles.astype(np.int32),
              "basis": basis_q, "basis_scale": basis_scale, "variance": (s ** 2).astype(np.float64),
              "expressions": expr_q, "expression_scale": expr_scale, "landmarks": landmarks,
              "region_map": region_map}
    arrays["metadata"] = np.array(json.dumps(dict(metadata, precision=precision(arrays, u, s, expressions,
                                                                                    neutral[source_row]))))
    return arrays


def _dilate(region_map: np.ndarray, margin: int) -> np.ndarray:
    """Background texels within ``margin`` texels of a labelled one take the nearest label."""
    background = region_map == REGIONS["background"]
    distance, (rows, cols) = ndi.distance_transform_edt(background, return_indices=True)
    out = region_map[rows, cols]
    out[distance > margin] = REGIONS["background"]
    return out


def _neck_and_scalp(region_map, uv, triangles, vertices, triangle_part) -> np.ndarray:
    """Split the back of the head (labelled hair) into scalp and neck: its triangles below the
    ear line and behind the jaw are skin."""
    back = triangle_part == REGIONS["hair"]
    centre = vertices[triangles].mean(axis=1)
    neck = back & (centre[:, 1] < -40.0)
    size = region_map.shape
    raster = rasterize(uv, triangles[neck], size)
    out = region_map.copy()
    out[raster.covered] = REGIONS["skin"]
    return out


def precision(arrays: dict, u: np.ndarray, s: np.ndarray, expressions: np.ndarray, mean: np.ndarray,
              faces: int = 200, seed: int = 0) -> dict:
    """What storing the basis and expressions as int16 loses, in mm: the largest and mean vertex
    error of ``faces`` random faces (all modes from the prior, expressions uniform in [0, 1])
    against the float64 model."""
    rng = np.random.default_rng(seed)
    rows = arrays["source_row"]
    basis = (arrays["basis"] * arrays["basis_scale"]).reshape(-1, 3, u.shape[1])[rows].reshape(-1, u.shape[1])
    expr = (arrays["expressions"] * arrays["expression_scale"]).reshape(-1, 3, expressions.shape[1])[rows]
    expr = expr.reshape(-1, expressions.shape[1])
    exact_expr = expressions.reshape(-1, 3, expressions.shape[1])[rows].reshape(-1, expressions.shape[1])
    worst, total = 0.0, 0.0
    for _ in range(faces):
        a = rng.standard_normal(u.shape[1]) * s
        e = rng.random(expressions.shape[1])
        error = (basis - u) @ a + (expr - exact_expr) @ e
        error += (arrays["neutral"].astype(np.float64)[rows] - mean).ravel()
        d = np.linalg.norm(error.reshape(-1, 3), axis=1)
        worst, total = max(worst, float(d.max())), total + float(d.mean())
    return {"max_mm": worst, "mean_mm": total / faces, "faces": faces}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", type=Path, help="folder with ict_facekit.npz, vertex_indices.json and LICENSE")
    parser.add_argument("--out", type=Path, default=MODEL_FILE)
    args = parser.parse_args(argv)
    arrays = convert(args.source)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    tmp.replace(args.out)
    shutil.copyfile(args.source / "LICENSE", args.out.parent / LICENSE_FILE.name)
    meta = json.loads(str(arrays["metadata"]))
    print(f"{args.out}: {args.out.stat().st_size / 1e6:.2f} MB, {len(arrays['uv'])} vertices, "
          f"{len(arrays['triangles'])} triangles, {arrays['basis'].shape[1]} identity modes, "
          f"{arrays['expressions'].shape[1]} expressions; int16 storage error max "
          f"{meta['precision']['max_mm']:.5f} mm, mean {meta['precision']['mean_mm']:.6f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
