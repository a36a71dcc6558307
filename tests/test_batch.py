"""Tests of mifaces.pipeline.batch (``mifaces batch`` on Dask) and mifaces.report.population.

Four tiny simulated captures (different seeds, 2 photographs at 128²,
ground-truth geometry, one model at texture 32²) and a fifth with a corrupt
manifest, measured on a local cluster, after a killed run, and on a Dask
scheduler started separately on the loopback interface.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from mifaces.pipeline.batch import find_captures, is_complete
from mifaces.cli.commands import main
from mifaces.options.measure import MeasureOptions
from mifaces.reflectance import FitOptions
from mifaces.report.population import robust_summary
from mifaces.runtime.status import NOT_FITTED

pytestmark = pytest.mark.slow

#: Options of every batch here: the cheapest measurement that runs every stage.
#: (the corrections' second fit left out: the subject is the batch, and it halves each measure)
OPTIONS = ["--brdf", "phong", "--geometry", "ground-truth", "--resolution", "32", "--spp", "2", "--no-interreflection",
           "--no-balance-lights"]
#: The options value those flags make.
RAN = MeasureOptions(models=("phong",), geometry="ground-truth", spp=2,
                     fit=FitOptions(resolution=32, interreflection=False, balance_lights=False))
GOOD = ["s0", "s1", "s2", "s3"]
#: Seconds any one wait for a subprocess may take.
TIMEOUT = 240


@pytest.fixture(scope="module")
def captures(small_capture, tmp_path_factory):
    """``good/`` with four captures s0..s3, and ``broken/`` whose manifest is cut short."""
    root = tmp_path_factory.mktemp("batch-captures")
    for seed, name in enumerate(GOOD):
        shutil.copytree(small_capture(f"batch-{name}", measurements=2, resolution=(128, 128), seed=seed + 1, spp=4,
                                      albedo_resolution=256), root / "good" / name)
    broken = root / "broken"
    broken.mkdir()
    text = (root / "good" / "s0" / "capture.json").read_text()
    (broken / "capture.json").write_text(text[: len(text) // 2])
    return root


def _batch(*args, options=OPTIONS) -> tuple[int, str]:
    result = CliRunner().invoke(main, ["batch", *map(str, args), *options])
    return result.exit_code, result.output


def _record(out: Path) -> dict:
    return json.loads((out / "batch.json").read_text())


def _command() -> list[str]:
    return [sys.executable, "-c", "import sys; from mifaces.cli.commands import main; sys.exit(main())"]


def test_robust_summary_flags_beyond_three_mads():
    s = robust_summary({"a": 1.0, "b": 1.1, "c": 0.9, "d": 1.05, "e": 5.0, "f": float("nan")})
    assert s["n"] == 5 and s["median"] == pytest.approx(1.05)
    assert s["mad"] == pytest.approx(1.4826 * 0.05)
    assert s["outliers"] == {"e": 5.0}
    assert robust_summary({"a": 1.0, "b": 9.0})["outliers"] == {}  # too few subjects for outliers


def test_find_captures_names_and_errors(captures, tmp_path):
    found = find_captures([captures / "good", captures / "broken"])
    assert list(found) == GOOD + ["broken"]
    with pytest.raises(FileNotFoundError, match="no capture"):
        find_captures([tmp_path])
    with pytest.raises(ValueError, match="unknown importer"):
        find_captures([captures / "good"], importer="nope")


def test_batch_failure_does_not_stop_the_others(captures, tmp_path):
    out = tmp_path / "out"
    code, output = _batch(captures / "good", captures / "broken", "--out", out, "--workers", "2")
    assert code != 0
    assert "broken: FAILED: CaptureError" in output and "not valid JSON" in output
    assert "1 capture(s) failed: broken" in output
    assert "Dask dashboard" in output
    record = _record(out)
    assert record["failed"] == ["broken"]
    assert "not valid JSON" in record["captures"]["broken"]["error"]
    for name in GOOD:
        assert f"{name}: done" in output
        assert record["captures"][name]["status"] == "done"
        assert is_complete(out / name, captures / "good" / name, RAN)
    assert not list(out.glob(".*.partial"))
    assert len({record["captures"][name]["worker"] for name in GOOD}) <= 2  # worker processes are reused
    # the options sent whole to the workers, recorded whole in the batch's record and every report
    assert MeasureOptions.from_record(record["options"]) == RAN
    for name in GOOD:
        report = json.loads((out / name / "report.json").read_text())
        assert MeasureOptions.from_record(report["options"]["requested"]) == RAN
    population = json.loads((out / "population.json").read_text())
    assert population["subjects"] == sorted(GOOD)
    phong = population["models"]["phong"]
    # A skin fit that ends as ``prior`` or ``defaults`` (on these tiny captures it
    # can, on some CPUs) is no measurement and is left out of the statistics.
    skin = {name: json.loads((out / name / "report.json").read_text())["models"]["phong"]["fit"]["skin"]["status"]
            for name in GOOD}
    fitted = sorted(name for name, status in skin.items() if status not in NOT_FITTED)
    assert len(fitted) >= 2, skin
    assert sorted(phong["parameters"]["skin"]["exponent"]["values"]) == fitted
    assert phong["status"]["converged"] >= 4
    assert phong["ground_truth"]["albedo"]["rmse_sampled"]["n"] == 4
    assert (out / "population.png").stat().st_size > 0 and "## phong" in (out / "population.md").read_text()


def test_resume_after_a_killed_run(captures, tmp_path):
    out = tmp_path / "out"
    args = [*_command(), "batch", str(captures / "good"), "--out", str(out), "--workers", "1", *OPTIONS]
    run = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + TIMEOUT
        while not list(out.glob("s*/report.json")) and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        os.killpg(run.pid, signal.SIGKILL)  # the command, its scheduler and its worker processes
        run.wait(30)
    finished = {p.parent.name: p.stat().st_mtime_ns for p in out.glob("s*/report.json")}
    assert 1 <= len(finished) < len(GOOD), "the run was to be killed after its first capture"
    code, output = _batch(captures / "good", "--out", out, "--resume")
    assert code == 0, output
    record = _record(out)
    for name in GOOD:
        expected = "skipped" if name in finished else "done"
        assert record["captures"][name]["status"] == expected
        assert is_complete(out / name, captures / "good" / name, RAN)
    assert {p.parent.name: p.stat().st_mtime_ns for p in out.glob("s*/report.json") if p.parent.name in finished} \
        == finished
    assert not list(out.glob(".*.partial"))
    assert json.loads((out / "population.json").read_text())["subjects"] == GOOD
    # a capture fitted with other options is no result of these: --resume measures it again
    other = dataclasses.replace(RAN, spp=3)
    assert not is_complete(out / "s0", captures / "good" / "s0", other)
    code, output = _batch(captures / "good" / "s0", "--out", out, "--resume", options=[*OPTIONS, "--spp", "3"])
    assert code == 0, output
    assert _record(out)["captures"]["s0"]["status"] == "done" and is_complete(out / "s0", captures / "good" / "s0",
                                                                             other)


def _dask(*args, cwd: Path) -> subprocess.Popen:
    """``dask scheduler ...`` or ``dask worker ...`` in this Python."""
    return subprocess.Popen([sys.executable, "-m", "dask", *args], cwd=cwd,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _scheduler_address(file: Path, scheduler: subprocess.Popen) -> str:
    """The address in Dask's scheduler file, once it is whole: Dask creates the file, then writes it."""
    deadline = time.monotonic() + TIMEOUT
    while time.monotonic() < deadline:
        assert scheduler.poll() is None, f"dask scheduler exited with code {scheduler.returncode}"
        try:
            return json.loads(file.read_text())["address"]
        except (FileNotFoundError, json.JSONDecodeError, KeyError):
            time.sleep(0.1)
    raise AssertionError(f"dask scheduler wrote no address to {file} within {TIMEOUT} s")


def test_batch_on_a_separate_scheduler(captures, tmp_path):
    file = tmp_path / "scheduler.json"
    processes = [_dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file",
                       str(file), cwd=tmp_path)]
    try:
        address = _scheduler_address(file, processes[0])
        assert address.startswith("tcp://127.0.0.1:")
        processes.append(_dask("worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--nworkers", "1",
                               "--no-dashboard", "--local-directory", str(tmp_path), cwd=tmp_path))
        out = tmp_path / "out"
        code, output = _batch(captures / "good" / "s0", captures / "good" / "s1", "--out", out, "--scheduler",
                              address)
        assert code == 0, output
        record = _record(out)
        workers = {record["captures"][name]["worker"] for name in ("s0", "s1")}
        assert len(workers) == 1 and not workers.pop().endswith(f":{os.getpid()}")  # the one outside worker
        assert all(is_complete(out / n, captures / "good" / n, RAN) for n in ("s0", "s1"))
    finally:
        for process in reversed(processes):
            process.terminate()
            try:
                process.wait(30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(10)
