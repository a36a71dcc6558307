"""validation/roles.py: defaults are chosen on development data, and the scripts that choose refuse report data."""

from __future__ import annotations

import ast
import re
import importlib
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
VALIDATION = ROOT / "validation"


@pytest.fixture
def roles(monkeypatch):
    monkeypatch.syspath_prepend(str(VALIDATION))
    return importlib.import_module("roles")


def test_the_roles(roles):
    assert roles.SIMULATED.is_development(100) and roles.SIMULATED.is_development(11)
    assert not roles.SIMULATED.is_development(0)  # the main job's default capture reports
    assert not roles.SURREY_FACES.is_development(2024) and roles.SURREY_FACES.is_development(7)
    shared = sorted(p.name for p in (ROOT.parent / "shared" / "data" / "yaleb").glob("yaleB*"))
    assert shared and all(roles.YALE.is_development(s) for s in shared)  # ../shared holds development subjects only
    assert not roles.YALE.is_development("yaleB11")
    assert roles.require_development(roles.SIMULATED, [100, 101], "x") == [100, 101]
    with pytest.raises(roles.ReportDataError, match=r"0, 3 are report simulated capture seeds"):
        roles.require_development(roles.SIMULATED, [100, 0, 3], "the tiling")


def _calls(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    return {node.func.id for node in ast.walk(tree) if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)}


def test_every_chooser_refuses_report_data(roles):
    for script in roles.CHOOSERS:
        assert {"refuse_report_data", "require_development"} & _calls(ROOT / script), script
    # a script with a tuning role or its own tuning seeds chooses something: it must be listed
    for path in VALIDATION.glob("*.py"):
        source = path.read_text()
        if path.name not in ("roles.py", "reproduce.py") and (
                '"--role"' in source or re.search(r"^TUNING_SEEDS? = ", source, re.M)):
            assert f"validation/{path.name}" in roles.CHOOSERS, path.name


@pytest.mark.parametrize("script, argv", [
    ("light_balance_measure", ["--seeds", "100", "0", "--role", "tuning"]),
    ("albedo_rounds", ["--seeds", "3"]),
    ("shape_depth", ["--seeds", "1", "--out", "shape_depth_tuning.json"]),
    ("refine_shape_default", ["--seed", "0", "--out", "refine_shape_default_512_tuning.json"]),
    ("refine_seeds", ["--seeds", "1", "--role", "training", "--out", "refine_seeds_train.json"]),
    ("light_calibration_bias", ["--seeds", "4"]),
    ("refine_judge", ["--seeds", "100", "0"]),
])
def test_a_tuning_run_on_report_seeds_stops_before_any_work(roles, monkeypatch, capsys, tmp_path, script, argv):
    monkeypatch.chdir(tmp_path)  # anything written would land here
    module = importlib.import_module(script)
    monkeypatch.setattr(sys, "argv", [f"{script}.py", *argv])
    with pytest.raises(SystemExit) as stop:
        module.main(argv) if "argv" in module.main.__code__.co_varnames else module.main()
    assert stop.value.code == 2
    assert "report simulated capture seed" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
