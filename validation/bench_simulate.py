"""Simulation time per measurement, and the light-calibration error of the simulated studio.

Two runs of :func:`mifaces.studio.simulate.simulate` with its defaults (512x512
pixels, 64 samples per pixel, a diffuse-light companion per measurement,
1024-texel albedo map):

1. a few measurements (``--measurements``, default 6: two lights) at 512x512;
2. the paper's preset (``--preset paper``: 22 measurements, 8 lights). If the
   first run predicts more than ``--budget`` seconds for it (default 600), a
   subset of the preset's measurements is simulated with the same settings
   instead and the preset's time is extrapolated from it (each measurement
   costs the same, each light its two steel-sphere pictures); the JSON and
   the printout say so.

For every light of both runs, the position calibrated from the steel-sphere
pictures (:func:`mifaces.capture.load_capture`) is compared with the ground
truth: error in mm and in percent of the light's distance from the head
centre. The first run's photographs make the README's figure
``docs/images/simulated_capture.png``.

Run:  python validation/bench_simulate.py [--measurements K] [--budget S] [--quick]
Writes validation/results/bench_simulate.json and docs/images/simulated_capture.png.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import tempfile
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import mitsuba as mi
import numpy as np

from mifaces.capture import load_capture, read_ground_truth
from mifaces.io.atomic import atomic_path, write_json
from mifaces.io.image_files import read_exr
from mifaces.studio.options import PRESETS, SimulationOptions
from mifaces.studio.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "validation" / "results"
FIGURE = ROOT / "docs" / "images" / "simulated_capture.png"


def run(path: Path, **kwargs) -> dict:
    """Simulate, then load (calibrating the lights); timings and per-light errors."""
    t0 = time.perf_counter()
    result = simulate(path, SimulationOptions(**kwargs), progress=True)
    t_load = time.perf_counter()
    capture = load_capture(path)
    load_seconds = time.perf_counter() - t_load
    truth = read_ground_truth(capture)
    head = truth.head_center
    lights = []
    for light in capture.lights:
        position = truth.light(light.name).position
        distance = float(np.linalg.norm(position - head))
        error = float(np.linalg.norm(light.position - position))
        lights.append({"light": light.name, "distance_mm": round(distance, 1), "error_mm": round(error, 2),
                       "error_percent": round(100 * error / distance, 3),
                       "ray_rms_mm": round(light.calibration.rms_residual, 2),
                       "spheres_used": len(light.calibration.spheres)})
    measurement_seconds = float(np.sum(result.render_seconds))
    return {"measurements": result.measurements, "lights": result.lights, "settings": kwargs,
            "seconds_total": round(time.perf_counter() - t0 - load_seconds, 2),
            "seconds_per_measurement": round(result.seconds_per_measurement, 3),
            "seconds_measurements": round(measurement_seconds, 2),
            # setup (model, albedo map) and the steel-sphere pictures of every light
            "seconds_other": round(result.seconds - measurement_seconds, 2),
            "seconds_load_and_calibrate": round(load_seconds, 2),
            "calibration": lights}


def figure(path: Path, out: Path, tile: int = 384) -> None:
    """A montage of the capture as the camera recorded it (sRGB): point-light photographs of the
    first four measurements, the first light's steel-sphere highlight picture, the first diffuse companion."""
    import colour
    import skimage.io
    import skimage.transform
    from PIL import Image, ImageDraw

    manifest = json.loads((path / "capture.json").read_text())
    m = manifest["measurements"]
    panels = [(f"{e['name']}: point light {e['light']}", path / e["image"]["path"]) for e in m[:4]]
    panels.append((f"{manifest['lights'][0]['name']}: steel spheres", path / manifest["lights"][0]["spheres"]
                   ["highlight"]["path"]))
    panels.append((f"{m[0]['name']}: diffuse light", path / m[0]["diffuse"]["path"]))
    tiles = []
    for label, file in panels:
        if file.suffix == ".exr":  # linear, as recorded (full scale 1): encode for display
            rgb = colour.cctf_encoding(np.clip(read_exr(file)[..., :3], 0, 1), function="sRGB")
        else:
            rgb = skimage.io.imread(file)[..., :3] / 255.0
        rgb = skimage.transform.resize(rgb, (tile, tile), anti_aliasing=True)
        image = Image.fromarray(np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8))
        ImageDraw.Draw(image).text((8, 6), label, fill=(255, 255, 255))
        tiles.append(np.asarray(image))
    rows = [np.concatenate(tiles[i:i + 3], axis=1) for i in (0, 3)]
    montage = np.concatenate(rows, axis=0)
    with atomic_path(out) as tmp:
        skimage.io.imsave(tmp, montage, check_contrast=False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--measurements", type=int, default=6, help="measurements of the 512x512 run")
    parser.add_argument("--budget", type=float, default=600.0, help="seconds the paper preset may take")
    parser.add_argument("--quick", action="store_true", help="256x256, 16 spp, 3 measurements (a smoke test)")
    parser.add_argument("--keep", type=Path, default=None, help="keep the captures in this folder")
    args = parser.parse_args()

    settings = dict(resolution=(512, 512), spp=64, companion="diffuse", seed=0)
    if args.quick:
        settings.update(resolution=(256, 256), spp=16)
        args.measurements = 3
    paper = PRESETS["paper"]["measurements"]
    paper_lights = math.ceil(paper / 3)
    with tempfile.TemporaryDirectory(prefix="bench_simulate_") as tmp:
        folder = args.keep or Path(tmp)
        print(f"1. {args.measurements} measurements at {settings['resolution'][0]}x{settings['resolution'][1]}")
        few = run(folder / "few", measurements=args.measurements, **settings)
        if not args.quick:
            figure(folder / "few", FIGURE)

        per_light = (few["seconds_other"]) / few["lights"]  # setup counted in: an upper bound per light
        predicted = paper * few["seconds_per_measurement"] + paper_lights * per_light
        print(f"2. paper preset ({paper} measurements, {paper_lights} lights): predicted {predicted:.0f} s")
        if predicted <= args.budget:
            measured = run(folder / "paper", preset="paper", **settings)
            paper_result = dict(measured, extrapolated=False)
        else:
            # the preset's first lights, three poses each, as many as the budget allows (at least one light)
            k = max(3, 3 * int(args.budget / (3 * few["seconds_per_measurement"] + per_light) / 3))
            k = min(k, paper)
            subset = run(folder / "paper_subset", measurements=k, **settings)
            seconds = (paper * subset["seconds_per_measurement"]
                       + paper_lights * subset["seconds_other"] / subset["lights"])
            paper_result = dict(subset, extrapolated=True, measured_measurements=k,
                                seconds_total=round(seconds, 1), measurements=paper, lights=paper_lights,
                                note=f"{predicted:.0f} s predicted > budget {args.budget:.0f} s: simulated {k} of "
                                     f"the preset's {paper} measurements with the same settings; seconds_total "
                                     f"extrapolated as {paper} x seconds_per_measurement + {paper_lights} x "
                                     "the subset's other seconds per light")

    errors = [light["error_percent"] for r in (few, paper_result) for light in r["calibration"]]
    result = {
        "benchmark": "mifaces simulate: time per measurement and light-calibration error",
        "machine": {"cpus": os.cpu_count(), "load_average_at_end": [round(x, 2) for x in os.getloadavg()],
                    "platform": platform.platform(), "variant": mi.variant(), "mitsuba": mi.__version__},
        "settings": {**settings, "albedo_resolution": 1024},
        "few_measurements_512": few,
        "paper_preset": paper_result,
        "light_calibration_error_percent": {"max": max(errors), "mean": round(float(np.mean(errors)), 3),
                                            "lights": len(errors)},
        "figure": str(FIGURE.relative_to(ROOT)),
    }
    if not args.quick:
        write_json(OUT / "bench_simulate.json", result)

    print(f"\n{'run':28s} {'meas.':>5s} {'lights':>6s} {'s/meas.':>8s} {'total s':>8s}")
    size = "x".join(str(v) for v in settings["resolution"])
    for name, r in ((f"{size}, {few['measurements']} measurements", few), ("paper preset", paper_result)):
        flag = " (extrapolated)" if r.get("extrapolated") else ""
        print(f"{name:28s} {r['measurements']:5d} {r['lights']:6d} {r['seconds_per_measurement']:8.2f} "
              f"{r['seconds_total']:8.1f}{flag}")
    if paper_result.get("extrapolated"):
        print(f"  {paper_result['note']}")
    print("\nlight calibration (error of the position from the steel spheres, % of the light distance)")
    for name, r in (("few", few), ("paper", paper_result)):
        print(f"  {name:6s} " + "  ".join(f"{l['light']} {l['error_percent']:.2f} %" for l in r["calibration"]))
    print(f"  max {max(errors):.2f} %, mean {np.mean(errors):.2f} % over {len(errors)} lights")
    if not args.quick:
        print(f"\nwrote {FIGURE} and {OUT / 'bench_simulate.json'}")


if __name__ == "__main__":
    main()
