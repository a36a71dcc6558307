"""How closely glTF's material reproduces each fitted BRDF (``mifaces export``), per region (SIMULATED).

Simulates a small capture (default truth: Cook–Torrance; ``--measurements``
photographs at ``--resolution``², ``--spp`` samples), runs ``mifaces measure``
on it with the true shapes and all four BRDF models (texture ``--texture``²),
and for every model and fitted region maps the region's BRDF onto glTF's
(:mod:`mifaces.export.material`) and measures the relative RMSE of f cos θo
over the hemisphere grid (:func:`mifaces.export.material.mapping_rmse`): the
whole BRDF with the region's mean albedo (``rmse``) and the glossy lobes alone
(``rmse_specular``). Also exports each model's face as ``.glb`` and records
its size. Writes ``validation/results/export.json``.

    python validation/export.py [--measurements 3] [--resolution 256] [--spp 16] [--texture 128] [--work DIR]

Machine: 2 CPU cores shared with other jobs; times are indicative only.
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import time
from pathlib import Path

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

from mifaces.export import export_face
from mifaces.export.material import FIT_GRID, mapping_rmse
from mifaces.io.atomic import write_json
from mifaces.model import load_model
from mifaces.model.regions import REGIONS, texel_regions_of_mesh
from mifaces.pipeline.measure import measure
from mifaces.reflectance.io import load_estimate
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import simulate
from mifaces.reflectance import FitOptions

RESULTS = Path(__file__).resolve().parent / "results" / "export.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--measurements", type=int, default=3)
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--texture", type=int, default=128)
    parser.add_argument("--work", type=Path, default=None)
    args = parser.parse_args()
    mifaces.set_variant("llvm_ad_rgb")
    work = args.work or Path(tempfile.mkdtemp(prefix="mifaces-export-"))
    t0 = time.perf_counter()
    simulate(work / "capture", SimulationOptions(measurements=args.measurements,
                                                 resolution=(args.resolution, args.resolution), spp=args.spp, seed=0),
             progress=False, force=True)
    measure(work / "m", work / "capture", geometry="ground-truth", spp=4, progress=False,
            options=FitOptions(resolution=args.texture))
    seconds = {"simulate_and_measure": time.perf_counter() - t0}
    models = {}
    for model in mifaces.brdf.NAMES:
        folder = work / "m" / "brdf" / model
        document = load_estimate(folder)
        albedo, label = document["albedo"], None
        regions = {}
        for region, fit in document["fit"].items():
            if fit["status"] == "prior":
                continue
            if label is None:
                face = load_model("builtin")
                label = texel_regions_of_mesh(face.region_map, face.uv, face.triangles, albedo.shape[0])
            where = label == REGIONS[region]
            mean_albedo = albedo[where].mean(axis=0) if where.any() else albedo.reshape(-1, 3).mean(axis=0)
            t = time.perf_counter()
            regions[region] = dict(mapping_rmse(document, region, mean_albedo), albedo=mean_albedo.tolist(),
                                   samples=fit["samples"], seconds=round(time.perf_counter() - t, 2))
        t = time.perf_counter()
        glb = export_face(folder, work / f"{model}.glb")[-1]
        models[model] = {"regions": regions, "glb_bytes": glb.stat().st_size,
                         "export_seconds": round(time.perf_counter() - t, 2),
                         "rmse_skin": regions.get("skin", {}).get("rmse"),
                         "rmse_specular_skin": regions.get("skin", {}).get("rmse_specular")}
        print(model, {r: (round(e["rmse"], 4), round(e["rmse_specular"], 3)) for r, e in regions.items()})
    write_json(RESULTS, {
        "what": "relative RMSE of f cos θo over the hemisphere grid between each fitted region BRDF (its Mitsuba "
                "plugin) and the glTF 2.0 material mifaces export writes for it (glTF's BRDF, Appendix B with "
                "KHR_materials_specular and KHR_materials_ior); rmse: whole BRDF with the region's mean albedo; "
                "rmse_specular: the glossy lobes alone",
        "simulated": True, "truth": "cooktorrance (simulator default)", "geometry": "ground-truth",
        "capture": {"measurements": args.measurements, "resolution": args.resolution, "spp": args.spp, "seed": 0},
        "texture": args.texture, "hemisphere_grid": FIT_GRID, "models": models, "seconds": seconds,
        "machine": f"{platform.machine()}, 2 shared CPU cores, no GPU"})
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
