"""validation/reproduce.py: every committed result has a command, and the quick ones still come out of it."""

from __future__ import annotations

import importlib
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
VALIDATION = ROOT / "validation"


@pytest.fixture
def reproduce(monkeypatch):
    monkeypatch.syspath_prepend(str(VALIDATION))
    return importlib.import_module("reproduce")


def test_every_result_file_has_a_command(reproduce):
    files = {p.name for p in (VALIDATION / "results").glob("*.json")}
    made = {name for entry in reproduce.REGISTRY for name in entry.outputs}
    assert files - made - set(reproduce.RECORDS) == set(), "result files no REGISTRY entry makes"
    assert made - files == set(), "REGISTRY entries whose result file is not committed"
    names = [e.name for e in reproduce.REGISTRY]
    assert len(names) == len(set(names))
    for entry in reproduce.REGISTRY:
        assert (ROOT / entry.argv[1]).is_file() or entry.argv[0] != "python", entry.name


def _quick_names() -> list[str]:
    """The registry's quick entries (read at collection, before any fixture runs)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.syspath_prepend(str(VALIDATION))
        return [e.name for e in importlib.import_module("reproduce").REGISTRY if e.quick]


@pytest.mark.parametrize("name", _quick_names())
def test_quick_results_reproduce(reproduce, name):
    """CI fails here when code that a quick result depends on changed and the result was not rerun:
    rerun it with ``python validation/reproduce.py NAME --record`` and commit the file. One test per
    entry, so that the two workers share them."""
    records = reproduce.reproduce([reproduce.BY_NAME[name]], echo=lambda line: None)
    bad = {r["file"]: r["differences"][:5] for r in records if r["status"] != "matches"}
    assert not bad, f"quick results that their scripts no longer reproduce: {json.dumps(bad, indent=1)}"


def test_a_planted_change_in_the_library_is_caught(reproduce):
    """Phong's normalisation (n+2)/2π written (n+1)/2π, in the library that brdf_energy.py integrates."""
    old, bug = "lobe = (n + 2.0) * dr.inv_two_pi", "lobe = (n + 1.0) * dr.inv_two_pi"

    def plant(main: Path):
        path = main / "mifaces" / "brdf" / "phong.py"
        source = path.read_text()
        assert source.count(old) == 1
        path.write_text(source.replace(old, bug))

    records = reproduce.reproduce([reproduce.BY_NAME["brdf_energy"]], plant=plant, echo=lambda line: None)
    assert [r["status"] for r in records] == ["differs"]
    assert any(d.startswith("/variants[0]/albedo") for d in records[0]["differences"])


def test_compare_tolerances_and_ignored_keys(reproduce):
    exact = reproduce.Entry("x", ("python", "validation/x.py"), ("x.json",), kind="deterministic")
    loose = reproduce.Entry("y", ("python", "validation/y.py"), ("y.json",), rtol=1e-3, ignore=("reason",))
    old = {"a": 1.0, "b": [1, 2], "seconds": 3.0, "provenance": {"commit": "x"}, "reason": "ftol", "s": "ok"}
    assert reproduce.compare(dict(old), old, exact) == []
    assert reproduce.compare(dict(old, a=1.0000001), old, exact) == ["/a: 1.0000001 rerun, 1.0 committed"]
    assert reproduce.compare(dict(old, a=1.0000001, reason="other"), old, loose) == []
    assert reproduce.compare(dict(old, a=1.01), old, loose) == ["/a: 1.01 rerun, 1.0 committed"]
    # wall times and provenance are never compared; structure and strings always are
    assert reproduce.compare(dict(old, seconds=9.0, provenance={}), old, exact) == []
    assert reproduce.compare(dict(old, b=[1]), old, loose) == ["/b: 1 items rerun against 2 committed"]
    assert reproduce.compare(dict(old, s="no"), old, loose) == ["/s: 'no' rerun, 'ok' committed"]
    # a looser tolerance for part of a file only
    part = reproduce.Entry("z", ("python", "validation/z.py"), ("z.json",), tolerances=(("/fit", 0.05, 0.0),))
    nested = {"fit": {"d": 1.0}, "exact": 1.0}
    assert reproduce.compare({"fit": {"d": 1.04}, "exact": 1.0}, nested, part) == []
    assert reproduce.compare({"fit": {"d": 1.06}, "exact": 1.0}, nested, part) == ["/fit/d: 1.06 rerun, 1.0 committed"]
    assert reproduce.compare({"fit": {"d": 1.0}, "exact": 1.001}, nested, part) == ["/exact: 1.001 rerun, 1.0 committed"]
    assert reproduce.compare({k: v for k, v in old.items() if k != "a"}, old, loose) == [
        "/a: only in the committed file"]


def test_stale_follows_the_code_hash(reproduce, tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    for name in ("brdf_energy.json", "model_span.json", "stale.json", "nobody_makes_me.json"):
        (results / name).write_text("{}")
    code = reproduce.provenance.code_hash(VALIDATION / "brdf_energy.py")
    reproduced = {"brdf_energy.json": {"status": "matches", "commit": "a" * 40, "code": code}}
    files = reproduce.stale(reproduced, results)
    assert set(files) == {"model_span.json", "nobody_makes_me.json"}
    assert "never reproduced" in files["model_span.json"]
    reproduced["brdf_energy.json"]["code"] = "0" * 64  # the code changed since
    assert "changed" in reproduce.stale(reproduced, results)["brdf_energy.json"]
    reproduced["brdf_energy.json"].update(code=code, status="differs")
    assert "differs" in reproduce.stale(reproduced, results)["brdf_energy.json"]


def test_provenance_records_where_a_result_came_from(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(VALIDATION))
    provenance = importlib.import_module("provenance")
    data_file = tmp_path / "input.bin"
    data_file.write_bytes(b"abc")
    out = tmp_path / "r.json"
    provenance.write_result(out, {"x": 1}, script=VALIDATION / "model_span.py", seeds=[7, 2024], inputs=[data_file],
                            argv=[str(VALIDATION / "model_span.py"), "--faces", "3"])
    written = json.loads(out.read_text())
    p = written["provenance"]
    assert written["x"] == 1
    assert p["command"] == "python validation/model_span.py --faces 3"
    assert p["seeds"] == [7, 2024] and len(p["commit"]) == 40
    assert p["inputs"] == {str(data_file): "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"}
    assert p["code"] == provenance.code_hash(VALIDATION / "model_span.py")
    deps = [str(d) for d in provenance.dependencies(VALIDATION / "model_span.py")]
    assert "validation/model_span.py" in deps and "mifaces/validation/shape_errors.py" in deps
    assert "validation/provenance.py" in deps  # model_span.py imports it


def test_every_mutation_still_finds_its_text(monkeypatch):
    """mutations.json can only be rerun while each mutation's original text occurs once in its file:
    a change to the code it mutates must move the mutation with it (mutations.check)."""
    monkeypatch.syspath_prepend(str(VALIDATION))
    mutations = importlib.import_module("mutations")
    mutations.check(mutations.MUTATIONS)
    broken = [(mid, area, path, "no such text", new, why) for mid, area, path, _, new, why in mutations.MUTATIONS[:1]]
    with pytest.raises(SystemExit, match="occurs 0 times"):
        mutations.check(broken)
