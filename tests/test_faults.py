"""Faults of a careless or hostile user (issue 16): one test per numbered case,
killed runs, and a property-based sweep of the BRDF models.

Each case names the behaviour before the fix in its docstring; the test
asserts the behaviour after it.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings, strategies as st

from mifaces import brdf
from mifaces.brdf import MAX_LOBES, ParameterError, validate_brdf
from mifaces.capture import CaptureError, load_capture
from mifaces.capture.calibration import CalibrationError, calibrate_light
from mifaces.cli.commands import main
from mifaces.io.atomic import write_json
from mifaces.io.image_files import read_exr, write_exr
from mifaces.render import check_render_size
from mifaces.io.result_set import SET_MANIFEST, TEST_PAUSE_ENV, ResultSetError, check_result_target, result_set, verify_set
from mifaces.reflectance.io import KIND, load_estimate
from mifaces.reflectance.result import FILES
from mifaces.shape.io import write_fit
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import simulate
from mifaces.studio.truth import default_brdf

#: The small capture of these tests: 128² pixels, two measurements, few samples.
SMALL = dict(measurements=2, resolution=(128, 128), spp=4, albedo_resolution=128)


@pytest.fixture(scope="module")
def capture(small_capture):
    return small_capture("faults", **SMALL)


def _copy(capture: Path, tmp_path: Path) -> Path:
    """A copy of ``capture`` whose manifest a test may change (the ground truth left out)."""
    copy = tmp_path / "copy"
    shutil.copytree(capture, copy, ignore=shutil.ignore_patterns("ground_truth"))
    return copy


def _edit(folder: Path, change) -> None:
    manifest = folder / "capture.json"
    data = json.loads(manifest.read_text())
    change(data)
    manifest.write_text(json.dumps(data))


def _run(*args) -> object:
    return CliRunner().invoke(main, ["--variant", "llvm_ad_rgb", *args])


# --------------------------------------------------------------------------------------------
# 1. Data loss: simulate over a capture
# --------------------------------------------------------------------------------------------
def test_1_simulate_never_replaces_a_real_capture(capture, tmp_path):
    """Before: `mifaces simulate OUT` replaced a real capture's capture.json and photographs."""
    real = _copy(capture, tmp_path)
    (real / SET_MANIFEST).unlink()  # as a capture mifaces did not write
    before = {p: p.read_bytes() for p in real.rglob("*") if p.is_file()}
    for force in (False, True):
        with pytest.raises(ResultSetError, match="did not write"):
            simulate(real, SimulationOptions(**SMALL), progress=False, force=force)
    assert {p: p.read_bytes() for p in real.rglob("*") if p.is_file()} == before


def test_1_simulate_over_a_simulated_capture_needs_force(capture):
    t = time.perf_counter()
    with pytest.raises(FileExistsError, match="--force"):
        simulate(capture, SimulationOptions(**SMALL), progress=False)
    assert time.perf_counter() - t < 5  # refused before any rendering
    result = _run("simulate", str(capture), "--resolution", "128x128", "--spp", "4", "--measurements", "2")
    assert result.exit_code == 1 and "--force" in result.output


# --------------------------------------------------------------------------------------------
# 2. Data loss: names that are paths
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["../../escaped_m00", "/tmp/abs", "shapes", "SHAPES", "m00_albedo", ".hidden", ""])
def test_2_measurement_names_do_not_become_paths(tmp_path, name):
    """Before: a measurement named ../../escaped_m00 wrote two levels above --out; one named
    `shapes` had its .json overwritten by the index."""
    out = tmp_path / "a" / "b" / "out"
    fit = SimpleNamespace(measurement=name, converged=True)
    with pytest.raises(ValueError, match="measurement name"):
        write_fit(out, fit, SimpleNamespace(name="builtin"))
    assert not any(tmp_path.rglob("*escaped*")) and not out.exists()


def test_2_capture_refuses_path_like_measurement_names(capture, tmp_path):
    copy = _copy(capture, tmp_path)
    _edit(copy, lambda d: d["measurements"][0].update(name="../../escaped_m00"))
    with pytest.raises(CaptureError, match="cannot name a file"):
        load_capture(copy, calibrate=False)


# --------------------------------------------------------------------------------------------
# 3. Outputs that do not belong together
# --------------------------------------------------------------------------------------------
def _brdf_set(folder: Path, resolution: int, force: bool = False) -> None:
    document = dict(default_brdf("cooktorrance"), resolution=resolution, albedo=FILES["albedo"])
    with result_set(folder, KIND, force=force) as staging:
        write_json(staging / FILES["brdf"], document)
        write_exr(staging / FILES["albedo"], np.full((resolution, resolution, 3), 0.5, np.float32))


def test_3_a_mixed_brdf_set_is_refused(tmp_path):
    """Before: a 512 brdf.json with the 128 albedo.exr of an earlier run rendered with exit 0."""
    a, b = tmp_path / "a", tmp_path / "b"
    _brdf_set(a, 8)
    _brdf_set(b, 16)
    assert load_estimate(a)["albedo"].shape == (8, 8, 3)
    shutil.copy(b / FILES["albedo"], a / FILES["albedo"])
    with pytest.raises(ResultSetError, match="albedo.exr is not the file written with the rest"):
        load_estimate(a)
    # a folder of an older mifaces (no set manifest): the resolutions must agree
    (a / SET_MANIFEST).unlink()
    with pytest.raises(ResultSetError, match="files of different runs"):
        load_estimate(a)


def test_3_an_interrupted_set_leaves_the_old_one_whole(tmp_path):
    out = tmp_path / "brdf"
    _brdf_set(out, 8)
    with pytest.raises(KeyboardInterrupt):
        with result_set(out, KIND, force=True) as staging:
            write_json(staging / FILES["brdf"], {"model": "phong"})
            raise KeyboardInterrupt
    assert load_estimate(out)["resolution"] == 8
    assert sorted(p.name for p in tmp_path.iterdir()) == ["brdf"]  # no staging folder left


def _kill_after(command: list[str], delay: float) -> None:
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    try:
        process.wait(timeout=delay)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()


def _consistent_brdf(out: Path) -> None:
    """A fitted BRDF folder that readers accept whole, or refuse by name."""
    try:
        data = load_estimate(out)
    except (ResultSetError, FileNotFoundError):
        return
    assert data["albedo"].shape[:2] == (data["resolution"],) * 2


def test_3_fit_brdf_killed_at_a_random_moment(capture, tmp_path):
    """Before: killed once brdf.json existed, fit-brdf left a 512 brdf.json with the 128 albedo map."""
    out = tmp_path / "brdf"
    cli = [str(Path(sys.executable).parent / "mifaces"), "fit-brdf", str(capture), "--out", str(out)]
    assert _run("fit-brdf", str(capture), "--out", str(out), "--resolution", "32").exit_code == 0
    assert load_estimate(out)["resolution"] == 32
    _kill_after(cli + ["--resolution", "48", "--force"], random.Random(16).uniform(3.0, 14.0))
    _consistent_brdf(out)
    assert verify_set(out, KIND) is not None
    # the next run tidies the leftovers and writes a whole set
    assert _run("fit-brdf", str(capture), "--out", str(out), "--resolution", "48", "--force").exit_code == 0
    assert load_estimate(out)["resolution"] == 48
    assert sorted(p.name for p in tmp_path.iterdir()) == ["brdf"]


def _kill_in_write_window(command: list[str], flag: Path, points: list[str], timeout: float = 240.0) -> None:
    """Run ``command`` with :data:`~mifaces.io.result_set.TEST_PAUSE_ENV` set to ``flag``: let it go on at each of
    ``points`` but the last, where it is killed, inside the write window and nowhere else."""
    log = flag.with_suffix(".log")
    with open(log, "wb") as output:
        process = subprocess.Popen(command, env=dict(os.environ, **{TEST_PAUSE_ENV: str(flag)}), stdout=output,
                                   stderr=subprocess.STDOUT, start_new_session=True)
    try:
        for i, point in enumerate(points):
            deadline = time.monotonic() + timeout
            while not flag.exists():
                if process.poll() is not None:
                    raise AssertionError(f"the command ended ({process.returncode}) before reaching {point!r}: "
                                         f"{log.read_text()[-2000:]}")
                assert time.monotonic() < deadline, f"the command did not reach {point!r} in {timeout} s"
                time.sleep(0.02)
            assert flag.read_text() == point
            if i < len(points) - 1:
                flag.unlink()  # go on to the next point
        assert process.poll() is None  # waiting at the last point
    finally:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    flag.unlink()
    log.unlink()


@pytest.mark.parametrize("points", [["staged"], ["staged", "swapping"]], ids=["staged", "swapping"])
def test_3_fit_brdf_killed_inside_the_write_window(capture, tmp_path, points):
    """A kill at each point of result_set's write window, reached for certain (test_3_fit_brdf_killed_at_a_random_
    moment may fall before or after it): with the new set staged, the previous set is untouched; with the
    previous set moved aside, the folder is absent (no reader sees part of a set). Either way the next run
    tidies up and leaves one whole set: the previous one, or the complete new one."""
    out = tmp_path / "brdf"
    fit = ["fit-brdf", str(capture), "--out", str(out), "--brdf", "phong"]
    assert _run(*fit, "--resolution", "16").exit_code == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    _kill_in_write_window([str(Path(sys.executable).parent / "mifaces"), "--variant", "llvm_ad_rgb", *fit,
                           "--resolution", "24", "--force"], tmp_path / "flag", points)
    staged = [p for p in tmp_path.iterdir() if p.name.startswith(".brdf.new-")]
    assert len(staged) == 1 and verify_set(staged[0], KIND) is not None  # the new set was whole, beside
    if points[-1] == "staged":
        assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
        assert load_estimate(out)["resolution"] == 16
    else:
        assert not out.exists()
        with pytest.raises(FileNotFoundError):
            load_estimate(out)
    check_result_target(out, KIND, force=True)  # what the next run does first
    assert load_estimate(out)["resolution"] == (16 if points[-1] == "staged" else 24)
    assert verify_set(out, KIND) is not None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["brdf"]


def test_3_simulate_killed_at_a_random_moment(tmp_path):
    """Before: re-simulating into a capture folder and killing it left the old manifest with new images."""
    out = tmp_path / "capture"
    options = ", ".join(f"{k}={v!r}" for k, v in SMALL.items())
    script = f"import mifaces; from mifaces.studio import SimulationOptions, simulate; " \
             f"simulate({str(out)!r}, SimulationOptions(seed={{}}, {options}), progress=False, force=True)"
    subprocess.run([sys.executable, "-c", script.format(1)], check=True, capture_output=True)
    first = (out / "images" / "m00_point.exr").read_bytes()
    first_diffuse = (out / "images" / "m00_diffuse.png").read_bytes()
    _kill_after([sys.executable, "-c", script.format(2)], random.Random(7).uniform(3.0, 12.0))
    manifest = verify_set(out, "capture")  # the old set, whole (or the new one, if it finished)
    assert manifest is not None and load_capture(out, calibrate=False).measurements
    old = (out / "images" / "m00_point.exr").read_bytes() == first
    assert old == ((out / "images" / "m00_diffuse.png").read_bytes() == first_diffuse)  # never half and half


# --------------------------------------------------------------------------------------------
# 4. Calibration that knows when it failed
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("picture", ["uniform", "saturated"])
def test_4_calibration_without_a_highlight_fails(capture, picture):
    """Before: a saturated or uniform highlight picture put the light at the camera, no error."""
    loaded = load_capture(capture, calibrate=False)
    spheres = next(light.spheres for light in loaded.lights if light.spheres is not None)
    calibrate_light(spheres, loaded.camera)  # the real pictures calibrate
    pixels = spheres.highlight.pixels
    bad = np.full_like(pixels, 0.3) if picture == "uniform" else np.minimum(pixels * 1e4 + 0.5, 1.0)
    with pytest.raises(CalibrationError, match="no distinct highlight|show a highlight"):
        calibrate_light(replace(spheres, highlight=replace(spheres.highlight, pixels=bad)), loaded.camera)


# --------------------------------------------------------------------------------------------
# 5. Parameters checked everywhere
# --------------------------------------------------------------------------------------------
BAD_PARAMETERS = [
    ("cooktorrance", "specular_reflectance", float("nan")), ("phong", "exponent", 1e9),
    ("cooktorrance", "roughness", -0.3), ("cooktorrance", "roughness", 0.0), ("cooktorrance", "roughness", np.inf),
    ("cooktorrance", "roughness", float("nan")), ("cooktorrance", "eta", -1.0), ("phong", "exponent", -5.0),
    ("lafortune", "cz", 1e6), ("ward", "alpha", {"value": 0.2}), ("ward", "alpha", True),
]


@pytest.mark.parametrize("model, name, value", [c for c in BAD_PARAMETERS if not isinstance(c[2], dict)])
def test_5_plugins_refuse_bad_parameters(jit_variant, model, name, value):
    """Before: NaN specular -> NaN pixels, Phong exponent 1e9 -> inf, roughness -0.3, 0, NaN, inf -> no
    highlight, eta -1 -> a brighter face, exponent -5 -> 2.7e25, cz 1e6 -> inf; all accepted."""
    with pytest.raises(RuntimeError, match=f"{name}.*(outside|not a)"):
        mi.load_dict({"type": model, name: value})
    bsdf = mi.load_dict({"type": model})
    params = mi.traverse(bsdf)
    if isinstance(value, float) and name in params and not isinstance(params[name], mi.Color3f):
        params[name] = value
        with pytest.raises(ParameterError, match=name):
            params.update()


@pytest.mark.parametrize("model, name, value", BAD_PARAMETERS)
def test_5_brdf_documents_are_validated(model, name, value):
    document = default_brdf(model)
    document["regions"]["lips"][name] = value
    with pytest.raises(ParameterError, match=f"region 'lips': {name}"):
        validate_brdf(document)


def test_5_render_refuses_non_finite_lights_and_angles(capture, tmp_path):
    """Before: --light nan nan nan rendered an all-NaN image, --yaw nan a black one; exit 0."""
    out = tmp_path / "brdf"
    _brdf_set(out, 8)
    for option in (["--light", "nan", "nan", "nan"], ["--yaw", "nan"], ["--intensity", "inf"],
                   ["--light-angles", "nan", "0"], ["--spp", "100000000"]):
        result = _run("render", str(out), str(capture), "--out", str(tmp_path / "img"), *option)
        assert result.exit_code == 1, option
        assert "Traceback" not in result.output and "must be" in result.output or "samples" in result.output
    assert not list(tmp_path.glob("img*"))


# --------------------------------------------------------------------------------------------
# 7. Captures: booleans, negative pixels, paths outside
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("fault, message", [
    ("width_true", "width: must be a number, not True"),
    ("negative", "negative values"),
    ("parent", "lies outside"),
    ("absolute", "absolute path"),
    ("symlink_outside", "lies outside"),
])
def test_7_capture_faults(capture, tmp_path, fault, message):
    """Before: `width: true` read as 1, all-negative EXR pixels accepted, ../ and absolute paths read."""
    copy = _copy(capture, tmp_path)
    image = copy / "images" / "m00_point.exr"
    if fault == "width_true":
        _edit(copy, lambda d: d["camera"].update(width=True))
    elif fault == "negative":
        write_exr(image, -np.abs(read_exr(image)) - 0.1)
    elif fault == "parent":
        shutil.copy(image, tmp_path / "outside.exr")
        _edit(copy, lambda d: d["measurements"][0]["image"].update(path="../outside.exr"))
    elif fault == "absolute":
        _edit(copy, lambda d: d["measurements"][0]["image"].update(path=str(image.resolve())))
    else:
        shutil.copy(image, tmp_path / "outside.exr")
        image.unlink()
        image.symlink_to(tmp_path / "outside.exr")
    with pytest.raises(CaptureError, match=message):
        load_capture(copy, calibrate=False)


# --------------------------------------------------------------------------------------------
# 8. Errors instead of tracebacks, and before the work
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("tamper, message", [
    (lambda d: d["regions"].pop("skin"), "no 'skin' region"),
    (lambda d: d["regions"]["skin"].update(roughness={"value": 0.3}), "roughness = .* is not a number"),
])
def test_8_tampered_brdf_json_is_a_message(capture, tmp_path, tamper, message):
    """Before: a brdf.json without a skin region, or with a parameter given as an object, ended in a
    KeyError or TypeError inside the renderer."""
    out = tmp_path / "brdf"
    _brdf_set(out, 8)
    data = json.loads((out / FILES["brdf"]).read_text())
    tamper(data)
    (out / FILES["brdf"]).write_text(json.dumps(data))
    (out / SET_MANIFEST).unlink()  # hand-edited: no longer a set mifaces wrote
    with pytest.raises(ParameterError, match=message):
        load_estimate(out)
    result = _run("render", str(out), str(capture), "--out", str(tmp_path / "img"))
    assert result.exit_code == 1 and "Traceback" not in result.output


@pytest.mark.parametrize("command", ["fit-brdf", "fit-shape", "simulate", "render"])
def test_8_unwritable_out_fails_before_the_work(capture, tmp_path, monkeypatch, command):
    """Before: an unwritable --out failed only after the whole fit or render had run."""
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    out = str(blocker / "out")

    def work(*args, **kwargs):
        raise AssertionError("the work started")

    for name in ("fit_brdf_model", "fit_shapes", "render_fitted", "load_capture"):
        monkeypatch.setattr(f"mifaces.cli.commands.{name}", work)
    args = {"fit-brdf": ["fit-brdf", str(capture), "--out", out], "fit-shape": ["fit-shape", str(capture), "--out", out],
            "simulate": ["simulate", out], "render": ["render", str(tmp_path), str(capture), "--out", out + "/img"]}
    result = _run(*args[command])
    assert result.exit_code == 1 and "not a folder" in result.output, result.output


# --------------------------------------------------------------------------------------------
# 9. Sizes bounded before allocation
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("resolution", [(100000, 100000), (20000, 20000)])
def test_9_huge_resolutions_are_refused_at_once(tmp_path, resolution):
    """Before: 100000² ran 5 s and died inside Mitsuba; 20000² with `sample_count should be a multiple`."""
    t = time.perf_counter()
    with pytest.raises(ValueError, match="larger than mifaces handles"):
        simulate(tmp_path / "out", SimulationOptions(resolution=resolution), progress=False)
    assert time.perf_counter() - t < 2
    with pytest.raises(ValueError, match="more than one render pass"):
        check_render_size(8192, 8192, 1024)


def test_9_exr_header_size_is_checked_before_reading(tmp_path):
    """Before: an EXR whose header claims 100000² made the loader allocate 37 GiB."""
    path = tmp_path / "huge.exr"
    write_exr(path, np.zeros((4, 4, 3), np.float32))
    raw = bytearray(path.read_bytes())
    for attribute in (b"dataWindow\0box2i\0", b"displayWindow\0box2i\0"):
        at = raw.index(attribute) + len(attribute) + 4  # after the size field: xmin, ymin, xmax, ymax
        raw[at + 8:at + 16] = np.array([99999, 99999], "<i4").tobytes()
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match="100000x100000 pixels is larger"):
        read_exr(path)


def test_9_symlink_loop_is_named(capture, tmp_path):
    """Before: a symlink loop was reported as `image file missing`."""
    copy = _copy(capture, tmp_path)
    image = copy / "images" / "m00_point.exr"
    image.unlink()
    image.symlink_to(image)
    with pytest.raises(CaptureError, match="symbolic link loop"):
        load_capture(copy, calibrate=False)


def test_9_lafortune_lobes_are_bounded():
    """Before: 50 Lafortune lobes were accepted (12x slower), no bound."""
    with pytest.raises(ParameterError, match=f"at most {MAX_LOBES} lobes"):
        brdf.model("lafortune", lobes=50)
    with pytest.raises(RuntimeError, match=f"at most {MAX_LOBES} lobes"):
        mi.load_dict({"type": "lafortune", "cxy_50": -0.5, "cz_50": 0.5, "exponent_50": 3.0})
    assert _run("fit-brdf", ".", "--out", "x", "--brdf", "lafortune", "--lobes", "50").exit_code == 2


# --------------------------------------------------------------------------------------------
# 10. Results into an existing empty folder (issue 27)
# --------------------------------------------------------------------------------------------
def _empty(tmp_path: Path, name: str) -> Path:
    folder = tmp_path / name
    folder.mkdir()
    return folder


def test_10_result_set_into_an_existing_empty_folder(tmp_path):
    """Before: check_result_target returned None for an empty folder, and result_set died on None.parent."""
    out = _empty(tmp_path, "brdf")
    assert check_result_target(out, KIND) == out
    _brdf_set(out, 16)
    assert verify_set(out, KIND) is not None and load_estimate(out)["resolution"] == 16
    assert sorted(p.name for p in tmp_path.iterdir()) == ["brdf"]  # nothing staged or set aside is left


def test_10_simulate_into_an_existing_empty_folder(tmp_path):
    """Before: `mifaces simulate OUT` with OUT an empty folder rendered everything, then died."""
    out = _empty(tmp_path, "capture")
    result = _run("simulate", str(out), "--resolution", "64x64", "--spp", "2", "--measurements", "1")
    assert result.exit_code == 0, result.output
    assert verify_set(out, "capture") is not None and len(load_capture(out, calibrate=False).measurements) == 1


def test_10_fit_brdf_and_render_into_existing_empty_folders(capture, tmp_path):
    """Before: `mifaces fit-brdf CAPTURE --out DIR` with DIR an empty folder fitted everything, then died."""
    out = _empty(tmp_path, "brdf")
    result = _run("fit-brdf", str(capture), "--out", str(out), "--brdf", "phong", "--resolution", "16")
    assert result.exit_code == 0, result.output
    assert verify_set(out, KIND) is not None and load_estimate(out)["resolution"] == 16
    images = _empty(tmp_path, "images")
    result = _run("render", str(out), str(capture), "--out", str(images / "novel"), "--spp", "1")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in images.iterdir()) == ["novel.exr", "novel.png"]


def test_10_fit_shape_into_an_existing_empty_folder(capture, tmp_path):
    """`mifaces fit-shape CAPTURE --out DIR` with DIR an empty folder writes the fit and the index there:
    the index lists the fit with the status the fit's file and the exit code give, and the SHA-256 of
    the files written."""
    from mifaces.io.result_set import file_sha256

    out = _empty(tmp_path, "shapes")
    result = _run("fit-shape", str(capture), "--out", str(out), "--measurements", "m00", "--iterations", "0.01")
    assert "Traceback" not in result.output and result.exit_code in (0, 1), result.output
    # a 1 % schedule may not converge (its shading unmatched): then no vertices, but the fit and the index
    converged = result.exit_code == 0
    assert converged or "1 fit(s) did not converge: m00" in result.output, result.output
    files = {"m00.json"} | ({"m00.npy"} if converged else set())
    assert files | {"shapes.json"} <= {p.name for p in out.iterdir()}
    entry = json.loads((out / "shapes.json").read_text())["measurements"]["m00"]
    assert entry["status"] == json.loads((out / "m00.json").read_text())["status"]
    assert (entry["status"] == "converged") == converged and entry["vertices"] == ("m00.npy" if converged else None)
    assert entry["sha256"] == {name: file_sha256(out / name) for name in files}


def test_10_measure_into_an_existing_empty_folder(capture, tmp_path):
    """`mifaces measure CAPTURE --out DIR` with DIR an empty folder writes the report and each model's set there."""
    out = _empty(tmp_path, "measure")
    result = _run("measure", str(capture), "--out", str(out), "--brdf", "phong", "--geometry", "ground-truth",
                  "--resolution", "16")
    assert result.exit_code == 0, result.output
    assert (out / "report.md").is_file() and verify_set(out / "brdf" / "phong", KIND) is not None


def test_10_import_into_an_existing_empty_folder(tmp_path):
    """`mifaces import diligent OBJECT OUT` with OUT an empty folder writes the import there."""
    from test_diligent import _fake_object

    _fake_object(tmp_path / "obj")
    out = _empty(tmp_path, "out")
    result = _run("import", "diligent", str(tmp_path / "obj"), str(out))
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == ["diligent.npz", "split.json"]


def test_10_batch_into_an_existing_empty_folder(tmp_path):
    """`mifaces batch INPUTS --out DIR` with DIR an empty folder records the run there (here: one capture
    that fails on its manifest, the cheap path through the same writer)."""
    broken = _empty(tmp_path, "broken")
    (broken / "capture.json").write_text('{"format": ')
    out = _empty(tmp_path, "batch")
    result = _run("batch", str(broken), "--out", str(out), "--workers", "1", "--brdf", "phong",
                  "--geometry", "ground-truth", "--resolution", "16")
    assert result.exit_code == 1 and "1 capture(s) failed: broken" in result.output, result.output
    record = json.loads((out / "batch.json").read_text())
    assert record["captures"]["broken"]["status"] == "failed" and record["failed"] == ["broken"]


# --------------------------------------------------------------------------------------------
# Property-based sweep: finite values and gradients over extreme directions
# --------------------------------------------------------------------------------------------
#: Cosines from grazing to normal, the extremes included.
COSINES = st.sampled_from([1e-7, 1e-5, 1e-3, 0.05, 0.5, 0.999, 1.0 - 1e-7, 1.0]) | st.floats(1e-7, 1.0)


def _direction(z: float, phi: float) -> list[float]:
    s = float(np.sqrt(max(0.0, 1.0 - z * z)))
    return [float(s * np.cos(phi)), float(s * np.sin(phi)), float(z)]


@st.composite
def in_range(draw, model):
    """Parameters of ``model`` within their ranges, each at a bound or inside; Lafortune's
    coefficients within the energy bound the fits keep (beyond it a lobe overflows float32)."""
    params = {}
    for p in model.specular_parameters():
        value = draw(st.sampled_from([p.lower, p.upper]) | st.floats(p.lower, p.upper))
        params[p.name] = value
    for name, exponent in model.energy_coupled().items():
        bound = float(model.coefficient_bound(params[exponent], np.log, np.exp))
        params[name] = float(np.clip(params[name], -bound, bound))
    return params


@pytest.mark.parametrize("name", brdf.NAMES)
def test_models_are_finite_over_extreme_directions(name):
    """Over parameters in their ranges (at the bounds or inside) and directions from grazing to normal:
    f finite and non-negative, the pdf finite and non-negative, a sampled direction a unit vector, and
    the derivatives of f with respect to both directions and of f + pdf with respect to every
    parameter finite; every one of them non-zero in some example (a derivative the gradient does not
    reach would pass as finite)."""
    mifaces.set_variant("llvm_ad_rgb")
    model = brdf.model(name, **({"lobes": 2} if name == "lafortune" else {}))
    kinds = {p.name: p.kind for p in model.specular_parameters()}
    reached = set()

    # derandomize: the same examples on every run, so CI is reproducible; what random runs found
    # stays as a regression test below
    @settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
    @given(params=in_range(model), zi=COSINES, zo=COSINES, phi_i=st.floats(0, 2 * np.pi),
           phi_o=st.floats(0, 2 * np.pi), u=st.floats(0, 0.999999), v=st.floats(0, 0.999999))
    def check(params, zi, zo, phi_i, phi_o, u, v):
        values = {k: dr.opaque(mi.Color3f if kinds[k] == "rgb" else mi.Float, x) for k, x in params.items()}
        values["diffuse_reflectance"] = dr.opaque(mi.Color3f, 0.5)
        wi, wo = mi.Vector3f(*_direction(zi, phi_i)), mi.Vector3f(*_direction(zo, phi_o))
        dr.enable_grad(wi, wo, *values.values())
        f = model.eval(wi, wo, values)
        pdf = model.pdf_specular(dr.detach(wi), dr.detach(wo), values)
        sampled = model.sample_specular(dr.detach(wi), mi.Float(u), mi.Point2f(u, v), values)
        dr.backward(dr.sum(f[0] + f[1] + f[2]) + dr.sum(pdf))
        assert np.all(np.isfinite(np.array(f))) and np.all(np.array(f) >= 0), (params, zi, zo)
        assert np.all(np.isfinite(np.array(pdf))) and np.all(np.array(pdf) >= 0)
        assert np.all(np.isfinite(np.array(sampled)))
        assert np.linalg.norm(np.array(sampled)) == pytest.approx(1.0, abs=1e-4)  # a direction
        for key, value in [("wi", wi), ("wo", wo), *values.items()]:
            grad = np.array(dr.grad(value))
            assert np.all(np.isfinite(grad)), (key, params, zi, zo)
            reached.update([key] if np.any(grad != 0) else [])

    check()
    assert reached == {"wi", "wo", *kinds, "diffuse_reflectance"}, reached


def test_lafortune_pdf_gradient_is_finite_when_lobe_weights_underflow():
    """Found by a random run of the sweep above: at grazing incidence (cos 1e-7) a lobe with n = 1e5
    has an albedo estimate of exp(-1.6e6) and a wide one of 1e-21; their sum squared underflowed
    float32 in the mixture's ∂(w/Σw), and ∂pdf/∂C was NaN. The shares are now normalised in log space."""
    mifaces.set_variant("llvm_ad_rgb")
    model = brdf.model("lafortune", lobes=2)
    params = {"cxy": 0.0, "cz": -1.000096755364482, "exponent": 1e5, "cxy_2": 0.0, "cz_2": 0.9266805448152129,
              "exponent_2": 3.0}
    values = {k: dr.opaque(mi.Float if k.startswith("exponent") else mi.Color3f, x) for k, x in params.items()}
    for value in values.values():
        dr.enable_grad(value)
    wi = wo = mi.Vector3f(*_direction(1e-7, 0.0))
    pdf = model.pdf_specular(wi, wo, values)
    dr.backward(dr.sum(pdf))
    assert np.isfinite(np.array(pdf)).all() and np.array(pdf)[0] > 0
    for key, value in values.items():
        assert np.all(np.isfinite(np.array(dr.grad(value)))), key
    # and right: the first lobe's share is 0 (and stays 0), the second's 1, so the pdf and its derivatives
    # are the second lobe's, (n + 1)/2π c^n about its axis +z (c = wo·z = 1e-7), written out here
    n, c, m = params["exponent_2"], 1e-7, params["cz_2"] * 1e-7  # m = |s|, s = (C_xy x, C_xy y, C_z z)
    lobe = (n + 1) / (2 * np.pi) * c ** n
    np.testing.assert_allclose(np.array(pdf), lobe, rtol=1e-4)  # (values near 1e-21: no absolute tolerance)
    np.testing.assert_allclose(np.array(dr.grad(values["exponent_2"])), lobe * (1 / (n + 1) + np.log(c)), rtol=1e-4)
    # C_xy tilts the axis by x/|s| per unit; each channel carries a third of the mean the axis uses
    tilt = (n + 1) / (2 * np.pi) * n * c ** (n - 1) / m / 3
    np.testing.assert_allclose(np.array(dr.grad(values["cxy_2"])).ravel(), tilt, rtol=1e-4)
    for key in ("cxy", "cz", "exponent", "cz_2"):
        np.testing.assert_allclose(np.array(dr.grad(values[key])), 0.0, atol=1e-25, err_msg=key)

