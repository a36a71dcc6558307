"""Kernel launches, compilation and execution time of the shape fit (paper sec. 4.2).

Each measurement of a simulated capture is fitted with
:func:`mifaces.shape.fit.fit_measurement` (the arguments
:func:`~mifaces.shape.fit.fit_shape` passes) under Dr.Jit's kernel history
(``dr.JitFlag.KernelHistory``). The history is read every time the fit calls
its progress hook (every few steps, with their number), so the launches are
counted per iteration and per stage (``pose``: feature points only;
``level<i>``: the image levels). Reading the history costs time (it copies
every kernel's IR), so the wall time and the execution share come from a
second, timed fit of the same measurement (warm) whose history is read once at
the end. Reported per measurement:

* ``launches_per_iteration`` (all iterations, and per stage) and the launches
  by kind (``JIT``, ``BlockReduce``, ``Memcpy``, ``Memset``, ...), with those on
  at most 1,000 elements;
* ``compile_s``: code generation and backend compilation of the kernels not
  found in the cache; ``compiled``: how many; ``cache_hits``;
* ``execution_s``: the kernels' own run time, and ``execution_share``, its share of the
  wall time (both of the timed fit);
* ``seconds``: wall time of the timed fit (``seconds_counted``: of the counted one);
  ``feature_rms_px`` and ``E``: the fit's final loss terms; ``vertex_rms_mm``, ``vertex_rms_aligned_mm``,
  ``normal_deg``: against the ground truth (the vertices of the true face
  that face the camera; as in ``validation/shape_estimation.py``).

The second and later measurements have the same sizes as the first: their
kernels should all come from the cache.

Run:  python validation/bench_shape_kernels.py [--capture DIR] [--measurements K]
      [--resolution N] [--iterations F] [--label after]
Without ``--capture``, a capture of K measurements (default 2) at N x N pixels
(default 256) is simulated into a temporary folder. Writes (merging by label)
validation/results/bench_shape_kernels.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from collections import Counter
from pathlib import Path

import mifaces  # noqa: F401  (first: libLLVM)  # isort: skip

import drjit as dr
import numpy as np

from mifaces.capture import load_capture
from mifaces.io.atomic import write_json
from mifaces.shape import ShapeSchedule, fit_measurement

from shape_estimation import ensure_capture, evaluated, same_topology_metrics, truth  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "validation" / "results" / "bench_shape_kernels.json"
#: Kernels on at most this many elements count as small.
SMALL = 1000


class KernelCounter:
    """A progress hook for :func:`fit_measurement`: the kernel history of every iteration."""

    def __init__(self):
        self.iterations, self.stages, self.steps = [], [], []
        self.stage = None

    def update(self, n=1):
        self.iterations.append(dr.kernel_history())
        self.stages.append(self.stage)
        self.steps.append(n)

    def set_postfix(self, stage=None, **_):
        if self.stages:
            self.stages[-1] = stage
        self.stage = stage


def summary(entries: list[dict], iterations: int) -> dict:
    """Launch counts by kind, compile and execution time of a kernel history."""
    kinds = Counter(str(e["type"]).split(".")[-1] for e in entries)
    jit = [e for e in entries if str(e["type"]).endswith("JIT")]
    compiled = [e for e in jit if not e.get("cache_hit", 0)]
    return {"launches": len(entries), "launches_per_iteration": len(entries) / max(iterations, 1),
            "by_kind_per_iteration": {k: v / max(iterations, 1) for k, v in sorted(kinds.items())},
            "small_per_iteration": sum(e.get("size", 0) <= SMALL for e in entries) / max(iterations, 1),
            "compiled": len(compiled), "cache_hits": len(jit) - len(compiled),
            "compile_s": sum(e.get("codegen_time", 0.0) + e.get("backend_time", 0.0) for e in compiled) / 1e3,
            "execution_s": sum(e.get("execution_time", 0.0) for e in entries) / 1e3}


def bench(capture_path: Path, factor: float, names=None) -> list[dict]:
    capture = load_capture(capture_path)
    model = mifaces.load_model("builtin")
    schedule = ShapeSchedule.scaled(factor)
    rows = []
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    for m in capture.measurements:
        if names and m.name not in names:
            continue
        counter = KernelCounter()
        dr.kernel_history()  # clear
        t0 = time.perf_counter()
        fit = fit_measurement(m, capture.camera, model, light=capture.light(m.light),
                              schedule=schedule, progress=counter, distances=capture.distances)
        counted = time.perf_counter() - t0
        outside = dr.kernel_history()  # after the last iteration: final visibility and evaluation
        everything = [e for it in counter.iterations for e in it] + outside
        row = {"measurement": m.name, "iterations": fit.iterations, "seconds_counted": counted,
               "status": fit.status, **summary(everything, fit.iterations), "stages": {}}
        for stage in dict.fromkeys(counter.stages):
            chunks = [(h, n) for h, s, n in zip(counter.iterations, counter.stages, counter.steps) if s == stage]
            # the first steps of a stage carry its setup (samples, blur, visibility): the later ones
            # are the steady state
            steady = [len(h) / n for h, n in chunks[1:]] or [len(h) / n for h, n in chunks]
            its = sum(n for _, n in chunks)
            row["stages"][stage] = {"iterations": its, "median_launches": sorted(steady)[len(steady) // 2],
                                    **summary([e for h, _ in chunks for e in h], its)}
        # the timed fit: the same measurement again (warm), its history read once at the end
        dr.kernel_history()
        t0 = time.perf_counter()
        fit_measurement(m, capture.camera, model, light=capture.light(m.light),
                        schedule=schedule, progress=False, distances=capture.distances)
        seconds = time.perf_counter() - t0
        timed = summary(dr.kernel_history(), fit.iterations)
        row.update({"seconds": seconds, "execution_s": timed["execution_s"], "compile_s_timed": timed["compile_s"],
                    "execution_share": timed["execution_s"] / seconds})
        gt = truth(capture_path, m.name)[0]
        mask = evaluated(model, gt, capture.camera)
        row.update({"feature_rms_px": fit.loss["feature_rms_px"], "E": fit.loss["E"],
                    **same_topology_metrics(model, fit.vertices_world.astype(np.float64), gt, capture.camera,
                                            mask)})
        print(f"{m.name}: {fit.iterations} it, {seconds:.1f} s timed ({counted:.1f} s counted), "
              f"{row['launches_per_iteration']:.0f} launches/it "
              f"({', '.join(f'{k} {v:.0f}' for k, v in row['by_kind_per_iteration'].items())}; "
              f"{row['small_per_iteration']:.0f} small), compiled {row['compiled']} "
              f"({row['compile_s']:.1f} s), cache hits {row['cache_hits']}, execution {row['execution_s']:.1f} s "
              f"({100 * row['execution_share']:.0f} %); lm {row['feature_rms_px']:.3f} px, E {row['E']:.4g}, "
              f"vRMS {row['vertex_rms_mm']:.2f} mm, normals {row['normal_deg']:.2f} deg", flush=True)
        for stage, s in row["stages"].items():
            print(f"    {stage}: {s['iterations']} it, median {s['median_launches']:.1f} launches/it, "
                  f"mean {s['launches_per_iteration']:.1f}", flush=True)
        rows.append(row)
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--capture", type=Path, help="a capture folder (default: simulate one)")
    ap.add_argument("--measurements", type=int, default=2)
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--iterations", type=float, default=0.25, help="factor on the default schedule")
    ap.add_argument("--only", nargs="*", help="measurement names to fit (default: all)")
    ap.add_argument("--label", default="after", help="key of this run in the JSON (e.g. before, after)")
    args = ap.parse_args()
    load = os.getloadavg()[0]  # the machine may be shared: its load before and after
    with tempfile.TemporaryDirectory() as tmp:
        path = args.capture or ensure_capture(Path(tmp) / "capture", measurements=args.measurements,
                                              resolution=(args.resolution, args.resolution))
        rows = bench(path, args.iterations, args.only)
    result = json.loads(OUT.read_text()) if OUT.is_file() else {}
    result[args.label] = {"capture": str(args.capture or f"simulated {args.measurements} x {args.resolution}^2"),
                          "iterations_factor": args.iterations, "threads": os.cpu_count(),
                          "machine": platform.platform(), "load_average_1min": [load, os.getloadavg()[0]],
                          "measurements": rows}
    write_json(OUT, result)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
