"""Pictures of the morphable models: the built-in mean face, three random faces, the SFM mean, region maps.

Usage::

    python validation/model_gallery.py docs/images [--spp 64] [--sfm PATH]

Writes, atomically, into the folder given:

- ``model_faces.png``: built-in mean, three random built-in faces (shape drawn
  from the prior; the built-in ICT model has no colour model, so each wears
  the simulator's painted skin, :func:`mifaces.studio.skin.paint_skin`), the
  Surrey Face Model mean (grey, it has no colour model either), rendered with
  Mitsuba's ``diffuse`` BSDF under a point light and a weak constant fill;
- ``model_builtin_mean.png``: the built-in mean face, larger, three-quarter view;
- ``model_regions.png``: the region maps of the built-in model and the SFM in
  texture space, with the region vocabulary as legend.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import mifaces  # first: libLLVM and the variant  # isort: skip

import mitsuba as mi
import numpy as np

from mifaces.io.image_files import write_png
from mifaces.model import load_model
from mifaces.model.regions import REGION_NAMES

REPO = Path(__file__).resolve().parents[1]
SFM = REPO.parent / "shared" / "models" / "sfm_3448" / "sfm_shape_3448.npz"

#: Display colours of the regions (sRGB), in label order.
REGION_COLOURS = np.array([
    [0.15, 0.15, 0.18],  # background
    [0.93, 0.76, 0.64],  # skin
    [0.80, 0.20, 0.25],  # lips
    [0.25, 0.55, 0.95],  # eyes
    [0.40, 0.25, 0.12],  # eyebrows
    [0.10, 0.10, 0.10],  # nostrils
    [0.45, 0.65, 0.45],  # beard
    [0.95, 0.80, 0.25],  # hair
])


def render_face(vertices, triangles, uv, albedo, frame, width=320, height=400, spp=64, azimuth=0.0):
    """Render one face: point light above-left of the camera plus a weak constant fill.

    ``frame`` is ``(target (3,), distance)`` in the model's millimetres.
    """
    from mifaces.model.mesh import mitsuba_mesh

    if albedo is None:
        albedo = np.full_like(vertices, 0.45)
    if albedo.shape != np.shape(vertices):  # an albedo map in texture space
        bsdf = {"type": "diffuse", "reflectance": {"type": "bitmap", "bitmap": mi.Bitmap(albedo.astype(np.float32)),
                                                   "raw": True}}
        mesh = mitsuba_mesh(vertices, triangles, uv, bsdf=bsdf)
    else:
        mesh = mitsuba_mesh(vertices, triangles, uv, albedo=albedo)
    target, distance = frame
    az = np.radians(azimuth)
    eye = target + distance * np.array([np.sin(az), 0.08, np.cos(az)])
    light = target + distance * np.array([np.sin(az - 0.5) * 0.9, 0.6, np.cos(az - 0.5)])
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 24,
                   "to_world": mi.ScalarTransform4f().look_at(origin=eye.tolist(), target=target.tolist(),
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "gaussian"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "face": mesh,
        "key": {"type": "point", "position": light.tolist(),
                "intensity": {"type": "rgb", "value": [3.2 * distance ** 2] * 3}},
        "fill": {"type": "constant", "radiance": {"type": "rgb", "value": [0.35] * 3}},
    })
    return np.array(mi.render(scene, spp=spp))[:, :, :3]


def face_frame(model, distance_factor=5.5):
    """Camera target and distance that frame the face (from its landmarks or its extent)."""
    v = model.shape_mean
    if len(model.landmarks) >= 10:
        p = v[model.landmarks[:, 1]]
        lo, hi = p.min(0), p.max(0)
        target = 0.5 * (lo + hi) + np.array([0.0, 8.0, 0.0])
        size = np.ptp(p[:, 1]) * 1.25
    else:
        target, size = v.mean(0), np.ptp(v[:, 1])
    return target, distance_factor * size


def region_image(region_map):
    return REGION_COLOURS[np.asarray(region_map)]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out", type=Path, help="folder for the PNGs, e.g. docs/images")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--sfm", type=Path, default=SFM, help="Surrey Face Model npz (skipped if absent)")
    args = parser.parse_args(argv)

    start = time.perf_counter()
    builtin = load_model("builtin")
    print(f"{builtin} (loaded in {time.perf_counter() - start:.1f} s)")
    sfm = load_model(args.sfm) if args.sfm.is_file() else None
    if sfm is None:
        print(f"Surrey Face Model not found at {args.sfm}; rendering the built-in model only", file=sys.stderr)

    from mifaces.studio.skin import paint_skin

    def skin(seed):
        return builtin.texture() if builtin.has_texture else paint_skin(builtin, np.random.default_rng(seed), 1024)

    frame = face_frame(builtin)
    tiles = [render_face(builtin.shape(), builtin.triangles, builtin.uv, skin(0), frame, spp=args.spp,
                         azimuth=20.0)]
    for seed in (1, 2, 3):
        vertices = builtin.shape(builtin.random_coefficients(seed)["shape"])
        tiles.append(render_face(vertices, builtin.triangles, builtin.uv, skin(seed), frame, spp=args.spp,
                                 azimuth=20.0))
    if sfm is not None:
        tiles.append(render_face(sfm.shape(), sfm.triangles, sfm.uv, None, face_frame(sfm, 3.4), spp=args.spp,
                                 azimuth=20.0))
    write_png(args.out / "model_faces.png", np.concatenate(tiles, axis=1))

    big = render_face(builtin.shape(), builtin.triangles, builtin.uv, skin(0), frame, width=480,
                      height=600, spp=args.spp, azimuth=35.0)
    write_png(args.out / "model_builtin_mean.png", big)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    from mifaces.io.atomic import save_figure

    maps = [("built-in (ICT head, atlas)", builtin.region_map)]
    if sfm is not None:
        maps.append(("Surrey Face Model (from its landmarks)", sfm.region_map))
    fig, axes = plt.subplots(1, len(maps), figsize=(4.2 * len(maps) + 1.6, 4.4), dpi=100)
    for ax, (title, rmap) in zip(np.atleast_1d(axes), maps):
        ax.imshow(region_image(rmap), extent=(0, 1, 1, 0), interpolation="nearest")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("u")
        ax.set_ylabel("v")
    fig.legend(handles=[Patch(color=REGION_COLOURS[i], label=name) for i, name in enumerate(REGION_NAMES)],
               loc="center right", fontsize=9, frameon=False)
    fig.subplots_adjust(left=0.06, right=0.83, wspace=0.25)
    save_figure(fig, args.out / "model_regions.png", dpi=None)
    print(f"wrote model_faces.png, model_builtin_mean.png, model_regions.png to {args.out} "
          f"in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
