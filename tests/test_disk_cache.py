"""mifaces' disk cache (:mod:`mifaces.runtime.disk_cache`): a simulated capture made once is copied,
not rendered again, for the same options and code; anything else is a miss."""

from __future__ import annotations

import importlib
import json
import warnings
from dataclasses import replace

import pytest

import mifaces  # noqa: F401  # isort: skip
from mifaces.io.result_set import verify_set
from mifaces.runtime import disk_cache
from mifaces.studio.options import SimulationOptions
from mifaces.studio.simulate import KIND, simulate

simulate_module = importlib.import_module("mifaces.studio.simulate")

TINY = SimulationOptions(measurements=1, resolution=(64, 48), spp=2, companion="diffuse", albedo_resolution=64)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv(disk_cache.ENV, str(folder))
    return folder


def _no_renders(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("rendered although the capture was cached")
    monkeypatch.setattr(simulate_module, "photograph_face", refuse)
    monkeypatch.setattr(simulate_module, "photograph_spheres", refuse)


def test_a_cached_capture_is_copied_not_rendered_again(tmp_path, cache, monkeypatch):
    first = simulate(tmp_path / "a", TINY, progress=False, cache=True)
    assert not first.cached
    _no_renders(monkeypatch)
    second = simulate(tmp_path / "b", TINY, progress=False, cache=True)
    assert second.cached and second.lights == first.lights
    a, b = verify_set(tmp_path / "a", KIND), verify_set(tmp_path / "b", KIND)
    assert a["info"] == b["info"] and a["files"] == b["files"]  # the same files, byte for byte
    # replacing a simulated capture takes force, cached or not
    with pytest.raises(FileExistsError):
        simulate(tmp_path / "b", TINY, progress=False, cache=True)
    assert simulate(tmp_path / "b", TINY, progress=False, cache=True, force=True).cached


def test_other_options_or_other_code_miss_the_cache(tmp_path, cache, monkeypatch):
    simulate(tmp_path / "a", TINY, progress=False, cache=True)
    assert not simulate(tmp_path / "b", replace(TINY, seed=1), progress=False, cache=True).cached
    disk_cache.code_fingerprint.cache_clear()
    monkeypatch.setattr(disk_cache, "code_fingerprint", lambda: "other code")
    assert not simulate(tmp_path / "c", TINY, progress=False, cache=True).cached


def test_the_fingerprint_follows_every_file_of_the_package(tmp_path, monkeypatch):
    package = tmp_path / "package"
    (package / "data").mkdir(parents=True)
    (package / "code.py").write_text("x = 1\n")
    (package / "data" / "model.npz").write_bytes(b"\0" * 16)
    monkeypatch.setattr(disk_cache, "_package_folders", lambda: [package])
    prints = []
    for change in (None, lambda: (package / "code.py").write_text("x = 2\n"),
                   lambda: (package / "data" / "model.npz").write_bytes(b"\1" * 16)):
        if change is not None:
            change()
        disk_cache.code_fingerprint.cache_clear()
        prints.append(disk_cache.code_fingerprint())
    disk_cache.code_fingerprint.cache_clear()
    assert len(set(prints)) == 3


def test_a_damaged_cached_capture_is_discarded_and_simulated_again(tmp_path, cache):
    simulate(tmp_path / "a", TINY, progress=False, cache=True)
    kept = disk_cache.lookup(KIND, {"options": disk_cache_record(TINY)})
    assert kept is not None
    image = next((kept / "images").iterdir())
    image.write_bytes(image.read_bytes()[:-10] + b"0123456789")  # a changed file: the set's checksum fails
    again = simulate(tmp_path / "b", TINY, progress=False, cache=True)
    assert not again.cached
    assert verify_set(disk_cache.lookup(KIND, {"options": disk_cache_record(TINY)}), KIND) is not None


def test_the_cache_can_be_off_and_keeps_a_few_folders(tmp_path, cache, monkeypatch):
    monkeypatch.setenv(disk_cache.ENV, disk_cache.OFF)
    simulate(tmp_path / "a", TINY, progress=False, cache=True)
    assert not cache.exists()
    monkeypatch.setenv(disk_cache.ENV, str(cache))
    monkeypatch.setattr(disk_cache, "KEEP", 2)
    for seed in range(3):
        simulate(tmp_path / f"s{seed}", replace(TINY, seed=seed), progress=False, cache=True)
    assert len([p for p in (cache / KIND).iterdir() if not p.name.startswith(".")]) == 2
    assert disk_cache.lookup(KIND, {"options": disk_cache_record(replace(TINY, seed=0))}) is None


def test_an_unwritable_cache_warns_and_the_run_goes_on(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv(disk_cache.ENV, str(blocker / "cache"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = simulate(tmp_path / "a", TINY, progress=False, cache=True)
    assert not result.cached and verify_set(result.path, KIND) is not None
    assert any("could not keep" in str(w.message) and disk_cache.ENV in str(w.message) for w in caught)


def test_measure_simulates_the_default_through_the_cache(tmp_path, monkeypatch):
    calls = []
    from mifaces.pipeline import measure as pipeline

    def fake(out, options=None, *, progress=True, force=False, cache=False):
        calls.append(cache)
        raise RuntimeError("stop here")
    monkeypatch.setattr(pipeline, "simulate", fake)
    with pytest.raises(RuntimeError, match="stop here"):
        pipeline.measure(tmp_path / "out", None, progress=False)
    assert calls == [True]


def disk_cache_record(options):
    from mifaces.options.fields import record
    return json.loads(json.dumps(record(options)))
