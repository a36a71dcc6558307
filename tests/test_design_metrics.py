"""validation/design_metrics.py: each of the redesign issue's counts on a small package written here, whose
sites are known without the script, and on the real tree against an independent count."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

TYPES = '''
from dataclasses import dataclass


@dataclass
class Light:
    name: str
    direction: object = None
    unknown: bool = False

    @property
    def directional(self):
        return self.direction is not None  # the light's own: not counted

    def towards(self):
        if self.unknown:  # self: not counted
            raise ValueError(self.name)
'''

USE = '''
import dataclasses
from dataclasses import replace

from .capture.types import Light
from .lights.point import PointLight


def branches(light, lights, l, x, a, b):
    if light.unknown:  # SITE if
        return a
    y = a if lights[0].directional else b  # SITE ternary
    if isinstance(l, Light):  # SITE isinstance
        pass
    elif x.kind == "point":  # x is no light
        pass
    elif isinstance(x, PointLight):  # SITE elif
        pass
    z = [m for m in lights if m.position is None]  # SITE comprehension
    w = x.unknown or light.estimated  # SITE boolean
    for key, source in lights.items():
        if source.guess is not None:  # SITE items
            pass
    light.kind = "point"  # an assignment, not a read
    count = sum(1 for p in params if p.kind == "rgb")  # a parameter's kind, no light
    return replace(light, name="n"), dataclasses.replace(l, name="m"), y, z, w, count  # REPLACE


def lamp_of(capture, name):
    lamp = capture.light(name)
    return lamp.intensity if lamp.environment else None  # SITE lamp


def big(a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15, a16):  # BIG
    return a1


def _private(a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12):
    return a1


class Public:
    def method(self, a1, a2, a3, a4, a5, a6, a7, a8, a9, *args, key=None, **kwargs):  # METHOD
        return a1


class _Hidden:
    def method(self, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11):
        return a1
'''

POINT = '''
class PointLight:
    def kind_of(self, light):
        return "unknown" if light.unknown else "known"  # inside mifaces/lights: not counted
'''

CLI = '''
import click


@click.command()
@click.option("--resolution", default=default(FitOptions, "resolution"), type=click.IntRange(8))  # RES1
@click.option("--normals/--no-normals", default=None)  # NORMALS1
def first(resolution, normals):
    pass


@click.command()
@click.option("-r", "--resolution", default=default(FitOptions, "resolution"), type=click.IntRange(8, 64))  # RES2
@click.option("--normals/--no-normals", default=None)  # NORMALS2
@click.option(f"--{name}", default=1)  # DYNAMIC
@click.option("--once", default=2)
def second(resolution, normals):
    pass
'''

MATERIAL = '''
def lobe(model, name, path, x):
    if model == "phong":  # CHECK model
        return 1
    if name in ("ward", "other"):  # CHECK name
        return 2
    if path.suffix == ".glb":  # not a model
        return 3
    if x == "cooktorrance":  # CHECK literal
        return 4
    return 0
'''

FIT = '''
def helper():
    return 0


@decorated
def fit_brdf(x, depth=0):  # FIT
    if depth:
        return x
    return fit_brdf(x, depth + 1)  # RECURSE
'''

PIPELINE = '''
import json

from .shape.io import load_geometry
from .reflectance import io as rio
from .export import export_face


def run(capture, f, out):
    json.load(f)
    load_geometry(capture, "ground-truth")  # READ geometry
    export_face(out / "brdf" / "phong", out / "face.glb")  # READ export
    export_face(f, out / "face.glb", source=str(out))  # WRITE export
    return rio.load_estimate(capture)  # READ estimate
'''


def _line(text: str, marker: str) -> int:
    """The line (1-based) of ``text`` that holds ``marker``; exactly one must."""
    lines = [i for i, line in enumerate(text.splitlines(), start=1) if marker in line]
    assert len(lines) == 1, marker
    return lines[0]


@pytest.fixture(scope="module")
def metrics(request):
    monkeypatch = pytest.MonkeyPatch()
    monkeypatch.syspath_prepend(str(ROOT / "validation"))
    yield importlib.import_module("design_metrics")
    monkeypatch.undo()


@pytest.fixture
def tree(tmp_path):
    files = {
        "mifaces/__init__.py": "",
        "mifaces/capture/__init__.py": "",
        "mifaces/capture/types.py": TYPES,
        "mifaces/use.py": USE,
        "mifaces/lights/__init__.py": "",
        "mifaces/lights/point.py": POINT,
        "mifaces/cli.py": CLI,
        "mifaces/long.py": "x = 1\n" * 460,
        "mifaces/export/__init__.py": "",
        "mifaces/export/material.py": MATERIAL,
        "mifaces/brdf/__init__.py": "",
        "mifaces/brdf/models.py": 'class Phong:\n    name = "phong"\n\n\nclass Ward:\n    name = "ward"\n\n\n'
                                  'class CookTorrance:\n    name = "cooktorrance"\n',
        "mifaces/reflectance/__init__.py": "",
        "mifaces/reflectance/estimate.py": FIT,
        "mifaces/pipeline.py": PIPELINE,
        "validation/with_insert.py": "import sys\nsys.path.insert(0, 'x')\n",
        "validation/without.py": "import sys\nprint(sys.path)\n",
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    return tmp_path


def test_branch_sites_on_a_light_s_kind_are_the_marked_ones(metrics, tree):
    sites = metrics.light_branches(tree)
    found = [(s["file"], s["line"], s["kind"]) for s in sites]
    expected = [("mifaces/use.py", _line(USE, f"# SITE {name}"), kind) for name, kind in (
        ("if", "if"), ("ternary", "ternary"), ("isinstance", "if"), ("elif", "elif"),
        ("comprehension", "comprehension if"), ("boolean", "boolean operand"), ("items", "if"), ("lamp", "ternary"))]
    assert found == sorted(expected)
    tests = {s["line"]: s["test"] for s in sites}
    assert tests[_line(USE, "# SITE ternary")] == "lights[0].directional"
    assert tests[_line(USE, "# SITE boolean")] == "x.unknown or light.estimated"
    assert {s["line"]: s["reads"] for s in sites}[_line(USE, "# SITE elif")] == ["isinstance"]
    assert metrics.per_file(sites) == {"mifaces/use.py": 8}


def test_replace_of_a_light_is_counted_and_of_anything_else_not(metrics, tree):
    replaces = metrics.light_replaces(tree)
    assert [(r["file"], r["line"]) for r in replaces] == [("mifaces/use.py", _line(USE, "# REPLACE"))]


def test_loose_modules_long_modules_and_parameters(metrics, tree):
    assert metrics.loose_modules(tree) == ["mifaces/cli.py", "mifaces/long.py", "mifaces/pipeline.py", "mifaces/use.py"]
    assert metrics.long_modules(tree) == [{"file": "mifaces/long.py", "lines": 460}]
    functions = {f["name"]: f for f in metrics.parameter_counts(tree)}
    assert functions["big"]["parameters"] == 16 and functions["big"]["line"] == _line(USE, "# BIG")
    assert functions["Public.method"]["parameters"] == 12  # self left out; *args, key, **kwargs one each
    assert functions["_private"]["parameters"] == 12 and not functions["_private"]["public"]
    assert not functions["_Hidden.method"]["public"] and functions["_Hidden.method"]["parameters"] == 11
    assert functions["Light.towards"]["parameters"] == 0
    assert [f["name"] for f in functions.values() if f["parameters"] >= 15] == ["big"]
    assert sorted(f["name"] for f in functions.values() if f["public"] and f["parameters"] > 10) == ["Public.method",
                                                                                                    "big"]


def test_fit_brdf_s_length_and_its_call_of_itself(metrics, tree):
    (fit,) = metrics.fit_brdf_size(tree)
    assert fit["file"] == "mifaces/reflectance/estimate.py" and fit["line"] == _line(FIT, "# FIT")
    assert fit["lines"] == 5  # the decorator, the def and three lines
    assert fit["calls_itself"] and fit["self_calls"] == [_line(FIT, "# RECURSE")]


def test_flags_declared_twice_and_the_copies_among_them(metrics, tree):
    duplicates = metrics.duplicate_flags(tree)
    assert {flag: [o["line"] for o in found] for flag, found in duplicates.items()} == {
        "--normals": [_line(CLI, "# NORMALS1"), _line(CLI, "# NORMALS2")],
        "--resolution": [_line(CLI, "# RES1"), _line(CLI, "# RES2")]}
    copies = metrics.copied_flags(duplicates)
    assert list(copies) == ["--resolution [default(FitOptions, 'resolution')]"]
    dynamic = [o for o in metrics.click_options(tree) if o["flag"] is None]
    assert [o["line"] for o in dynamic] == [_line(CLI, "# DYNAMIC")]


def test_export_name_checks_sys_path_and_pipeline_reads(metrics, tree):
    checks = metrics.export_name_checks(tree)
    assert [(c["file"], c["line"]) for c in checks] == [
        ("mifaces/export/material.py", _line(MATERIAL, f"# CHECK {k}")) for k in ("model", "name", "literal")]
    assert metrics.sys_path_inserts(tree) == [{"file": "validation/with_insert.py", "lines": [2]}]
    reads = metrics.pipeline_reads(tree)
    assert [(r["line"], r["function"], r["reads_its_output"]) for r in reads] == [
        (_line(PIPELINE, "# READ geometry"), "mifaces.shape.io.load_geometry", False),
        (_line(PIPELINE, "# READ export"), "mifaces.export.export_face", True),
        (_line(PIPELINE, "# WRITE export"), "mifaces.export.export_face", False),
        (_line(PIPELINE, "# READ estimate"), "mifaces.reflectance.io.load_estimate", False)]


def test_measure_writes_targets_and_is_deterministic(metrics, tree):
    data = metrics.measure(tree)
    assert data == metrics.measure(tree)
    m = data["metrics"]
    assert m["light_branches"]["count"] == 8 and m["light_branches"]["met"] is False
    assert m["loose_modules"]["count"] == 4 and m["loose_modules"]["target"] == 2 and m["loose_modules"]["met"] is False
    assert m["fit_brdf_lines"]["count"] == 5 and m["fit_brdf_calls_itself"]["count"] is True
    assert m["pipeline_reads"]["count"] == 1 and len(m["pipeline_reads"]["pipeline_calls"]) == 4
    assert len(metrics.summary_rows(data)) == len(m)


def test_the_real_tree(metrics):
    data = metrics.measure(ROOT)
    m = data["metrics"]
    independent = len([p for p in (ROOT / "mifaces").glob("*.py") if p.name != "__init__.py"])
    assert m["loose_modules"]["count"] == independent
    # issue 49's targets, met: no function of 15 or more parameters, no public one of more than 10,
    # no module over 450 lines
    for key in ("functions_15_parameters", "public_over_10_parameters", "long_modules"):
        assert m[key]["count"] == 0, m[key]["sites"]
    # issue 49's target, met: no code outside lights/ and light_estimation/ asks a light its kind
    # or copies it with fields reset by hand (the scanner itself is tested on the trees above)
    assert m["light_branches"]["count"] == 0, m["light_branches"]
    assert m["light_replaces"]["count"] == 0, m["light_replaces"]
    assert m["light_branches"]["files"] == len(m["light_branches"]["per_file"])
    assert sum(m["light_branches"]["per_file"].values()) == m["light_branches"]["count"]
