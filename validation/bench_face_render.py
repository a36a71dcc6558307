"""The simulator's face photograph rendered with the Cook-Torrance plugin against Mitsuba's
built-in BSDFs, side by side in one process (issue 11: at most 1.2x).

The scene is a face photograph as :func:`mifaces.studio.simulate.simulate` renders one
with its defaults: the built-in face (subject and studio drawn with seed 0, a pose of the
first light drawn as the simulator draws them), the simulator's Cook-Torrance ground truth
per region over the 1024-texel albedo map, the studio camera and point light, the ``path``
integrator of :data:`mifaces.studio.scene.INTEGRATOR`; 512 x 512 pixels, 64 samples per
pixel. It is rendered with three BSDFs per region, on the same meshes:

* ``cooktorrance``: the mifaces plugin (Python, Dr.Jit), as the simulator renders it;
* ``roughplastic``: Mitsuba's built-in rough dielectric coating over a diffuse base
  (Beckmann, ``alpha`` = the region's roughness, ``int_ior`` = its eta, the albedo map as
  the diffuse reflectance, ``nonlinear`` off): the closest built-in material;
* ``blendbsdf``: Mitsuba's ``diffuse`` (the albedo map) and ``roughconductor`` (Beckmann,
  same alpha) blended half and half: a built-in diffuse-plus-glossy sum.

The built-in materials are stand-ins with the same structure (a Lambertian term, a Beckmann
lobe, an importance-sampled mixture), not the same reflectance: the comparison is of cost.
Per BSDF: the scene's load time (``mi.load_dict``, plugin instantiation) and the render time
(``mi.render`` to a NumPy image), the median of ``--repeats`` runs taken in turn (the
machine may be shared; the load average is recorded), and the ratios plugin / built-in.

Run:  python validation/bench_face_render.py [--resolution N] [--spp S] [--repeats K]
Writes validation/results/bench_face_render.json.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import mitsuba as mi
import numpy as np

from mifaces.io.atomic import write_json
from mifaces.model import load_model
from mifaces.render import region_bsdf, region_meshes
from mifaces.studio.photograph import albedo_texture
from mifaces.studio.scene import point_light, scene, set_up_studio
from mifaces.studio.subject import head_pose, make_subject
from mifaces.studio.truth import default_brdf

OUT = Path(__file__).resolve().parent / "results" / "bench_face_render.json"


def face_scene(resolution: int, spp: int):
    """The region meshes, the simulator's truth, the albedo texture, the studio and the light."""
    model = load_model("builtin")
    rng = np.random.default_rng(0)  # drawn from in the simulator's order: subject, studio, pose
    subject = make_subject(model, rng, 1024)
    texture = albedo_texture(subject.albedo)
    studio = set_up_studio(resolution, resolution, subject.head, 6, rng, spp)
    light, pose_index = studio.schedule[0]
    pose = head_pose(model, subject, pose_index, rng)
    vertices = pose.vertices.astype(np.float32)
    parts = region_meshes(model, vertices, model.vertex_normals(vertices))
    return parts, default_brdf("cooktorrance"), texture, studio, light


def bsdf(kind: str, truth: dict, region: str, texture) -> dict:
    """A region's BSDF: the plugin's (as the simulator builds it) or a built-in stand-in."""
    if kind == "cooktorrance":
        return region_bsdf(truth, region, texture)
    p = truth["regions"].get(region, truth["regions"]["skin"])
    if kind == "roughplastic":
        return {"type": "roughplastic", "distribution": "beckmann", "alpha": float(p["roughness"]),
                "int_ior": float(p["eta"]), "nonlinear": False, "diffuse_reflectance": texture}
    return {"type": "blendbsdf", "weight": 0.5, "a": {"type": "diffuse", "reflectance": texture},
            "b": {"type": "roughconductor", "distribution": "beckmann", "alpha": float(p["roughness"])}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolution", type=int, default=512)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    load = os.getloadavg()[0]
    parts, truth, texture, studio, light = face_scene(args.resolution, args.spp)
    kinds = ("cooktorrance", "roughplastic", "blendbsdf")
    times = {k: {"load_s": [], "render_s": []} for k in kinds}
    for repeat in range(args.repeats + 1):  # the first round compiles the kernels: not counted
        for kind in kinds:
            meshes = {key: part.mesh(bsdf(kind, truth, part.region, texture)) for key, part in parts.items()}
            t0 = time.perf_counter()
            loaded = mi.load_dict(scene(studio, meshes, point_light(studio, light), args.spp))
            t1 = time.perf_counter()
            image = np.array(mi.render(loaded, spp=args.spp, seed=repeat))
            t2 = time.perf_counter()
            assert np.all(np.isfinite(image)), kind
            if repeat:
                times[kind]["load_s"].append(t1 - t0)
                times[kind]["render_s"].append(t2 - t1)
    rows = {}
    for kind in kinds:
        rows[kind] = {k: float(np.median(v)) for k, v in times[kind].items()}
        rows[kind]["runs"] = times[kind]
    plugin = rows["cooktorrance"]
    ratios = {ref: {"render": plugin["render_s"] / rows[ref]["render_s"],
                    "load_and_render": (plugin["load_s"] + plugin["render_s"]) /
                                       (rows[ref]["load_s"] + rows[ref]["render_s"])}
              for ref in kinds[1:]}
    for kind in kinds:
        print(f"{kind:<13} load {rows[kind]['load_s']:6.2f} s  render {rows[kind]['render_s']:6.2f} s", flush=True)
    for ref, r in ratios.items():
        print(f"cooktorrance / {ref}: render {r['render']:.2f}x, load + render {r['load_and_render']:.2f}x")
    write_json(OUT, {"scene": "simulate() defaults: built-in face, seed 0, first light, Cook-Torrance truth",
                     "resolution": args.resolution, "spp": args.spp, "repeats": args.repeats,
                     "variant": mi.variant(), "mitsuba": mi.__version__, "threads": os.cpu_count(),
                     "machine": platform.platform(), "load_average_1min": [load, os.getloadavg()[0]],
                     "bsdfs": rows, "ratios": ratios})
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
