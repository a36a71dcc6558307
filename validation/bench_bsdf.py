"""Benchmark of the BSDF plugins and of the BRDF array API.

1. Render time of each mifaces plugin against Mitsuba's built-in
   ``roughplastic`` (Beckmann) in the same scene (scenes/sphere.xml) at the
   same resolution and spp; ratio = plugin / built-in (target <= 1.5).
2. Array-API throughput (samples/s) of each model on 10^6 and 10^7 random
   direction pairs, forward and forward+backward (gradient of the summed
   value with respect to every scalar parameter), against a numpy
   implementation of the same formulas written here; numpy's gradient is the
   forward-difference Jacobian of scipy's default (P + 1 evaluations).
   ratio = Dr.Jit samples/s / numpy samples/s (target >= 10).

Run:  python validation/bench_bsdf.py [--quick]
Writes validation/results/bench_bsdf.json and prints the tables.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import drjit as dr
import mitsuba as mi
import numpy as np

from mifaces import brdf
from mifaces.io.atomic import write_json
from mifaces.render.scenes import scene_path

OUT = Path(__file__).resolve().parent / "results"


# ---------------------------------------------------------------- numpy peer
def np_half(wi, wo):
    h = wi + wo
    return h / np.linalg.norm(h, axis=1, keepdims=True)


def np_phong(wi, wo, p):
    r = wi * [-1, -1, 1]
    c = np.clip(np.sum(r * wo, axis=1), 0, None)
    return p["diffuse"] / np.pi + p["specular"] * ((p["exponent"] + 2) / (2 * np.pi) * c ** p["exponent"])[:, None]


def np_fresnel(cos_i, eta):
    sin_t2 = (1 - cos_i ** 2) / eta ** 2
    cos_t = np.sqrt(np.clip(1 - sin_t2, 0, None))
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs ** 2 + rp ** 2)


def np_cooktorrance(wi, wo, p):
    h = np_half(wi, wo)
    m = p["roughness"]
    c = h[:, 2]
    tan2 = (h[:, 0] ** 2 + h[:, 1] ** 2) / c ** 2
    d = np.exp(-tan2 / m ** 2) / (np.pi * m ** 2 * c ** 4)
    g = np.minimum(1, np.minimum(2 * c * wo[:, 2] / np.sum(wo * h, 1), 2 * c * wi[:, 2] / np.sum(wi * h, 1)))
    f = np_fresnel(np.sum(wi * h, 1), p["eta"])
    return p["diffuse"] / np.pi + p["specular"] * (d * f * g / (4 * wi[:, 2] * wo[:, 2]))[:, None]


def np_ward(wi, wo, p):
    h = np_half(wi, wo)
    a = p["alpha"]
    c = h[:, 2]
    tan2 = (h[:, 0] ** 2 + h[:, 1] ** 2) / c ** 2
    hh = 2 + 2 * np.sum(wi * wo, 1)
    return p["diffuse"] / np.pi + p["specular"] * (np.exp(-tan2 / a ** 2) / (np.pi * a ** 2 * hh * c ** 4))[:, None]


def np_lafortune(wi, wo, p):
    base = p["cxy"] * (wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1]) + p["cz"] * wi[:, 2] * wo[:, 2]
    return p["diffuse"] / np.pi + (np.clip(base, 0, None) ** p["exponent"])[:, None] * np.ones(3)


CASES = {
    "phong": (np_phong, {"specular_reflectance": 0.2, "exponent": 30.0}),
    "cooktorrance": (np_cooktorrance, {"specular_reflectance": 1.0, "roughness": 0.3, "eta": 1.4}),
    "ward": (np_ward, {"specular_reflectance": 0.2, "alpha": 0.2}),
    "lafortune": (np_lafortune, {"cxy": -0.9, "cz": 0.9, "exponent": 20.0}),
}
NP_NAMES = {"specular_reflectance": "specular", "diffuse_reflectance": "diffuse"}


def timed(fn, repeats):
    """Best of ``repeats`` timings after a warm-up (which compiles the Dr.Jit
    kernel): the least disturbed run, for both sides alike."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def bench_array_api(sizes, repeats):
    rows = []
    rng = np.random.default_rng(0)
    for n in sizes:
        v = rng.normal(size=(2, n, 3))
        v[:, :, 2] = np.abs(v[:, :, 2]) + 0.05
        v /= np.linalg.norm(v, axis=2, keepdims=True)
        wi_np, wo_np = v[0].astype(np.float32), v[1].astype(np.float32)
        wi, wo = mi.Vector3f(wi_np.T), mi.Vector3f(wo_np.T)
        for name, (np_fn, values) in CASES.items():
            model = brdf.model(name)
            scalars = {k: v for k, v in values.items() if k in {p.name for p in model.parameters() if p.kind == "float"}}
            np_params = {NP_NAMES.get(k, k): np.float32(v) for k, v in values.items()}
            np_params["diffuse"] = np.array([0.5, 0.35, 0.3], dtype=np.float32)

            def dr_params():
                p = {k: mi.Float(v) for k, v in values.items()}
                p["diffuse_reflectance"] = mi.Color3f(0.5, 0.35, 0.3)
                return p

            def dr_forward():
                dr.eval(model.eval(wi, wo, dr_params()))
                dr.sync_thread()

            def dr_backward():
                p = dr_params()
                dr.enable_grad(*[p[k] for k in scalars])
                f = model.eval(wi, wo, p)
                dr.backward(dr.sum(f, axis=None))
                dr.eval([dr.grad(p[k]) for k in scalars])
                dr.sync_thread()

            def np_forward():
                return np_fn(wi_np, wo_np, np_params)

            def np_backward():
                f0 = np_fn(wi_np, wo_np, np_params).sum()
                grads = []
                for k in scalars:
                    key = NP_NAMES.get(k, k)
                    q = dict(np_params)
                    step = np.float32(1e-3) * max(abs(float(q[key])), 1e-2)
                    q[key] = q[key] + step
                    grads.append((np_fn(wi_np, wo_np, q).sum() - f0) / step)
                return grads

            # agreement of the two implementations before timing them
            ours = np.array(model.eval(wi, wo, dr_params())).T
            theirs = np_forward()
            rel = np.abs(ours - theirs).max() / np.abs(theirs).max()
            assert rel < 1e-3, f"{name}: numpy peer disagrees ({rel:.2e})"
            t = {k: timed(f, repeats) for k, f in
                 [("dr_fwd", dr_forward), ("dr_bwd", dr_backward), ("np_fwd", np_forward), ("np_bwd", np_backward)]}
            rows.append({"model": name, "samples": n,
                         "drjit_fwd_per_s": n / t["dr_fwd"], "numpy_fwd_per_s": n / t["np_fwd"],
                         "drjit_fwdbwd_per_s": n / t["dr_bwd"], "numpy_fwdbwd_per_s": n / t["np_bwd"],
                         "ratio_fwd": t["np_fwd"] / t["dr_fwd"], "ratio_fwdbwd": t["np_bwd"] / t["dr_bwd"]})
            print(f"  {name:<13} n={n:>9,d}  fwd {n / t['dr_fwd'] / 1e6:8.1f} M/s vs numpy {n / t['np_fwd'] / 1e6:6.1f} M/s"
                  f" ({rows[-1]['ratio_fwd']:5.1f}x)   fwd+bwd {n / t['dr_bwd'] / 1e6:7.1f} M/s vs numpy "
                  f"{n / t['np_bwd'] / 1e6:6.1f} M/s ({rows[-1]['ratio_fwdbwd']:5.1f}x)", flush=True)
    return rows


def bench_render(res, spp, repeats):
    rows = []
    times = {}
    for name in ["roughplastic", *brdf.NAMES]:
        scene = mi.load_file(str(scene_path("sphere")), bsdf=name, res=res, spp=spp)

        def render():
            dr.eval(mi.render(scene, spp=spp))
            dr.sync_thread()

        times[name] = timed(render, repeats)
    for name in brdf.NAMES:
        rows.append({"plugin": name, "seconds": times[name], "roughplastic_seconds": times["roughplastic"],
                     "ratio": times[name] / times["roughplastic"]})
        print(f"  {name:<13} {times[name] * 1e3:8.1f} ms vs roughplastic {times['roughplastic'] * 1e3:8.1f} ms"
              f"  ratio {rows[-1]['ratio']:.2f}", flush=True)
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, for a smoke test")
    args = parser.parse_args()
    sizes = [10 ** 5] if args.quick else [10 ** 6, 10 ** 7]
    res, spp, repeats = (64, 16, 2) if args.quick else (512, 64, 7)
    print(f"variant {mi.variant()}")
    print(f"render: scenes/sphere.xml {res}x{res}, {spp} spp, best of {repeats}")
    render_rows = bench_render(res, spp, repeats)
    print(f"array API: best of {repeats}")
    api_rows = bench_array_api(sizes, repeats)
    result = {"variant": mi.variant(), "render": render_rows, "array_api": api_rows,
              "render_setup": {"res": res, "spp": spp, "repeats": repeats}}
    if not args.quick:
        write_json(OUT / "bench_bsdf.json", result)
        print(f"wrote {OUT / 'bench_bsdf.json'}")


if __name__ == "__main__":
    main()
