"""docs/results.md is generated from validation/results/*.json by validation/results_doc.py."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "validation" / "results_doc.py"


def _module():
    spec = importlib.util.spec_from_file_location("results_doc", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _pipeline(wall_s: float) -> dict:
    return {"command": "mifaces measure", "note": "fake",
            "runs": {"warm": {"wall_s": wall_s, "stages_s": {"simulate": 1.5, "total": wall_s},
                              "skin_cooktorrance_error": {"specular_reflectance": 0.0123}}}}


def _fake_results(folder: Path, wall_s: float = 97.8) -> Path:
    results = folder / "validation" / "results"
    results.mkdir(parents=True, exist_ok=True)
    (results / "bench_pipeline.json").write_text(json.dumps(_pipeline(wall_s)))
    (results / "zz_unknown.json").write_text(json.dumps({"alpha": 1, "beta": [2]}))
    return results


def test_committed_results_doc_is_up_to_date():
    done = subprocess.run([sys.executable, str(SCRIPT), "--check"], capture_output=True, text=True)
    assert done.returncode == 0, "docs/results.md is out of date: run python validation/results_doc.py\n" + done.stderr


def test_table_follows_the_json(tmp_path):
    doc = _module()
    results = _fake_results(tmp_path)
    out = tmp_path / "docs" / "results.md"
    assert doc.main(["--results", str(results), "--out", str(out)]) == 0
    first = out.read_text()
    assert "| wall time (s) | 97.8 |" in first
    assert "| skin Cook–Torrance ρs error | 1.23 % |" in first
    # a key the layout expects but the file lacks shows as a dash, not a crash
    assert "| peak memory (MiB) | — |" in first
    # an unknown layout gets one line with its top-level keys
    assert "`alpha`, `beta`" in first
    assert doc.main(["--results", str(results), "--out", str(out), "--check"]) == 0

    # the same input gives the same file, byte for byte
    assert doc.main(["--results", str(results), "--out", str(out)]) == 0
    assert out.read_text() == first

    (results / "bench_pipeline.json").write_text(json.dumps(_pipeline(123.4)))
    assert doc.main(["--results", str(results), "--out", str(out), "--check"]) == 1
    assert out.read_text() == first  # --check writes nothing
    assert doc.main(["--results", str(results), "--out", str(out)]) == 0
    second = out.read_text()
    assert "| wall time (s) | 123.4 |" in second and "97.8" not in second
    assert sorted(p.name for p in out.parent.iterdir()) == ["results.md"]  # no temporary file left behind


def test_a_page_embeds_a_table_that_follows_the_json(tmp_path):
    doc = _module()
    results = _fake_results(tmp_path)
    out = tmp_path / "docs" / "results.md"
    page = tmp_path / "docs" / "speed.md"
    page.parent.mkdir(parents=True)
    page.write_text("# Speed\n\nHand-written.\n\n<!-- generated: bench_pipeline.json -->\nold table\n"
                    "<!-- end generated -->\n\nMore prose.\n")
    assert doc.main(["--results", str(results), "--out", str(out)]) == 0
    text = page.read_text()
    assert "old table" not in text and "| wall time (s) | 97.8 |" in text
    assert text.startswith("# Speed\n\nHand-written.\n") and text.endswith("<!-- end generated -->\n\nMore prose.\n")
    assert "`validation/results/bench_pipeline.json`" in text  # the section names its file
    assert doc.main(["--results", str(results), "--out", str(out), "--check"]) == 0

    # the JSON moves: --check fails on the page, and a write follows it
    (results / "bench_pipeline.json").write_text(json.dumps(_pipeline(123.4)))
    assert doc.main(["--results", str(results), "--out", str(out), "--check"]) == 1
    assert doc.main(["--results", str(results), "--out", str(out)]) == 0
    assert "| wall time (s) | 123.4 |" in page.read_text() and "97.8" not in page.read_text()
    (results / "bench_pipeline.json").write_text(json.dumps(_pipeline(97.8)))
    assert doc.main(["--results", str(results), "--out", str(out)]) == 0
    page.write_text(page.read_text().replace("97.8", "97.9"))  # a hand edit inside the table
    assert doc.main(["--results", str(results), "--out", str(out), "--check"]) == 1
    assert "97.9" in page.read_text()  # --check writes nothing
    assert doc.main(["--results", str(results), "--out", str(out)]) == 0
    assert "| wall time (s) | 97.8 |" in page.read_text()


def test_a_changed_layout_does_not_crash(tmp_path):
    doc = _module()
    results = tmp_path / "validation" / "results"
    results.mkdir(parents=True)
    (results / "real_yaleb.json").write_text(json.dumps({"overall": [1, 2], "subjects": "none"}))
    (results / "truths.json").write_text(json.dumps([1, 2, 3]))
    (results / "broken.json").write_text("{not json")
    out = tmp_path / "results.md"
    assert doc.main(["--results", str(results), "--out", str(out)]) == 0
    text = out.read_text()
    assert "## Held-out relighting on the Yale face database: `real_yaleb.json`" in text
    assert "Not readable as JSON" in text


def test_rankings_over_subjects_call_ties_within_their_spread(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "validation"))
    import results_format as f

    # b beats a by 0.01 on every subject: no tie; c is 0.001 better than b on average but worse on one
    # subject of three, with a spread that covers the gap: a tie
    per = {"a": [0.30, 0.31, 0.29], "b": [0.29, 0.30, 0.28], "c": [0.30, 0.291, 0.275]}
    assert f.ranked_with_ties(per) == "c 0.289 ≈ b 0.290 < a 0.300"
    assert f.spread([1.0, 3.0]) == (2.0, 2 ** 0.5) and f.spread([1.0]) is None
    # a difference alike on every subject is never a tie, however small
    assert f.ranked_with_ties({"x": [0.1, 0.2, 0.3], "y": [0.1001, 0.2001, 0.3002]}, 4) == "x 0.2000 < y 0.2001"
