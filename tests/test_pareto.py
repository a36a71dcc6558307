"""validation/pareto.py: each setting's errors over several seeds, and fronts through their means."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "validation" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _point(measurements, seed, wall_s, error):
    errors = {key: error for key in ("brdf_skin", "albedo_rmse", "environment_rmse", "heldout_rmse")}
    return {"measurements": measurements, "resolution": 256, "spp": 16, "seed": seed, "wall_s": wall_s,
            "models": {"cooktorrance": errors}}


def test_fronts_go_through_the_means_over_the_seeds():
    pareto = _load("pareto")
    # the slow setting's errors are 0.01 and 0.05 (mean 0.03); the quick one's 0.02 and 0.02
    points = [_point(2, 3, 10.0, 0.02), _point(6, 3, 30.0, 0.01), _point(2, 4, 12.0, 0.02), _point(6, 4, 34.0, 0.05)]
    settings = pareto.summary(points, "cooktorrance")
    assert [(s["measurements"], s["seeds"]) for s in settings] == [(2, [3, 4]), (6, [3, 4])]
    slow = settings[1]
    assert slow["wall_s"] == pytest.approx(32.0)
    assert slow["brdf_skin"] == pytest.approx({"mean": 0.03, "min": 0.01, "max": 0.05})
    fronts = pareto.fronts(settings)
    # seed 3 alone would put the slow setting on the front; its mean does not
    assert fronts["brdf_skin"]["front"] == [[2, 256, 16]]
    assert fronts["brdf_skin"]["default_on_front"] is None  # the default (6 / 512 / 64) was not run


def test_results_doc_shows_the_spread():
    pareto, doc = _load("pareto"), _load("results_doc")
    points = [_point(2, 3, 10.0, 0.02), _point(2, 4, 12.0, 0.04)]
    settings = pareto.summary(points, "cooktorrance")
    data = {"model": "cooktorrance", "seeds": [3, 4], "options": {"geometry": "ground-truth"},
            "grid": {"measurements": [2], "resolutions": [256], "spp": [16]}, "summary": settings,
            "fronts": pareto.fronts(settings), "default": pareto.DEFAULT}
    lines = "\n".join(doc.sec_pareto(data))
    assert "| 2 / 256 / 16 | 11 | 3.00 % (2.00 %–4.00 %) | 0.0300 (0.0200–0.0400) |" in lines
    assert "seeds 3, 4" in lines
    assert doc.pareto_command(data).endswith("--geometry ground-truth --seeds 3 4")
