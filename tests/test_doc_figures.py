"""Every figure of README.md and docs/*.md comes from validation/results/ or is marked as a citation
(validation/doc_figures.py, run by ``validation/results_doc.py --check``)."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
VALIDATION = ROOT / "validation"


def _load(name: str):
    sys.path.insert(0, str(VALIDATION))
    spec = importlib.util.spec_from_file_location(name, VALIDATION / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(name, module)  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


figures = _load("doc_figures")


def _site(tmp_path: Path, page: str, results: dict[str, dict] | None = None) -> tuple[Path, Path]:
    """A repository in miniature: docs/page.md, and validation/results/ with the given files."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "page.md").write_text(page, encoding="utf-8")
    folder = tmp_path / "validation" / "results"
    folder.mkdir(parents=True)
    for name, data in (results or {}).items():
        (folder / name).write_text(json.dumps(data), encoding="utf-8")
    return tmp_path / "docs" / "page.md", folder


def _unbacked(page: Path, results: Path) -> list[str]:
    return [f"{f.line}: {f.text}" for f in figures.check([page], results)]


def test_the_committed_docs_have_no_unbacked_figure():
    pages = figures.pages_beside(ROOT / "docs" / "results.md")
    assert ROOT / "README.md" in pages and ROOT / "docs" / "results.md" not in pages
    unbacked = figures.check(pages)
    assert not unbacked, "figures backed by no result their section names:\n" + figures.report(unbacked)


def test_a_planted_figure_in_a_copy_of_a_page_is_reported(tmp_path):
    text = (ROOT / "docs" / "trust.md").read_text(encoding="utf-8")
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("## Mutations")) + 2
    lines.insert(at, "The reference tests take 12.345 s and catch 97.51 % of the mutations.")
    page, _ = _site(tmp_path, text)
    before = set(_unbacked(page, figures.RESULTS))
    page.write_text("\n".join(lines) + "\n", encoding="utf-8")
    shifted = {f"{int(n) + (int(n) > at)}:{rest}" for n, rest in (b.split(":", 1) for b in before)}
    assert set(_unbacked(page, figures.RESULTS)) - shifted == {f"{at + 1}: 12.345 s", f"{at + 1}: 97.51 %"}


def test_a_figure_is_backed_by_the_json_its_section_names(tmp_path):
    results = {"bench.json": {"runs": {"warm": {"wall_s": 97.84, "error": 0.0123, "world_mm": 2.44}}}}
    page, folder = _site(tmp_path, "# Page\n\n## Timing\n\nFrom `validation/results/bench.json`: the job took "
                                   "97.8 s, skin's error was 1.23 % (1.2 %) and the face 2.44 mm off.\n\n"
                                   "## Elsewhere\n\nThe job took 97.8 s.\n", results)
    assert _unbacked(page, folder) == ["9: 97.8 s"]  # the second section names no result


def test_a_figure_that_contradicts_its_json_is_reported(tmp_path):
    results = {"bench.json": {"runs": {"warm": {"wall_s": 97.84, "error": 0.0123, "world_mm": 2.44}}}}
    page, folder = _site(tmp_path, "## Timing\n\nFrom [bench.json](../validation/results/bench.json): the job "
                                   "took 437 s, skin's error was 1.81 %; 97.8 mm (a time is not a length).\n",
                         results)
    assert _unbacked(page, folder) == ["3: 437 s", "3: 1.81 %", "3: 97.8 mm"]


@pytest.mark.parametrize("line, reported", [
    ("Skin's index is 1.38 (Weyrich et al. 2006). <!-- cite: Weyrich et al. 2006 -->", []),
    ("Skin's index is 1.38 (Weyrich et al. 2006).", ["1.38"]),
    ("It was 2.5 mm off; skin's index is 1.38 <!-- cite: Weyrich et al. 2006 --> by 4.5 %.", ["2.5 mm", "4.5 %"]),
    ("| 1.38 <!-- cite: Weyrich et al. 2006 --> | 2.5 mm |", ["2.5 mm"]),
    ("An empty citation: 1.38 <!-- cite: -->", ["1.38"]),
])
def test_a_marked_citation_is_not_reported(tmp_path, line, reported):
    page, folder = _site(tmp_path, f"## Skin\n\n{line}\n")
    assert _unbacked(page, folder) == [f"3: {r}" for r in reported]


def test_what_is_not_a_figure(tmp_path):
    page, folder = _site(tmp_path, "\n".join([
        "## Not figures (paper sec. 4.3–5.3, eq. 7.2, issue 22)",
        "",
        "Run `mifaces measure --resolution 512 --spp 64 --tolerance 0.25` on 512² photographs at 64 spp,",
        "seeds 3 4 5, on Python >= 3.10 with glTF 2.0 and LLVM 16 ([a link](https://x.org/v1.5/a_2.5.html)).",
        "<!-- a comment with 3.5 mm in it -->",
        "```",
        "took 12.5 s",
        "```",
        "Regions m01 and yaleB01_P00A+035E+40; 16 modes; 2 × height.",
    ]) + "\n")
    assert _unbacked(page, folder) == []


def test_units_ranges_and_chains(tmp_path):
    page, folder = _site(tmp_path, "The faces lay 2.2 and 2.6 mm off, 10.0–10.3 %, 3.47 -> 2.20 %, 13.4× faster, "
                                   "0.33/0.18 mm, 89,000 and 0.286.\n")
    texts = [f.text for f in figures.figures([page], folder)]
    assert texts == ["2.2 mm", "2.6 mm", "10.0 %", "10.3 %", "3.47 %", "2.20 %", "13.4 ×", "0.33 mm", "0.18 mm",
                     "0.286"]


def test_names_in_a_section_and_its_headings(tmp_path):
    results = {"a_tuning.json": {"x": 0.286}, "a_test.json": {"y_deg": 5.2}, "b.json": {"z_pct": 7.5}}
    page, folder = _site(tmp_path, "\n".join([
        "# Page", "", "The introduction names `a_{tuning,test}.json`.", "",
        "## One", "", "0.286 and 5.2°.", "",
        "### One and a half", "", "Also 5.2°; 7.5 % is [b's](results.md#the-b-table-bjson).", "",
        "## Two", "<!-- figures: validation/results/b.json -->", "", "7.5 % again; 0.5 % is not in b.json.",
    ]) + "\n", results)
    assert _unbacked(page, folder) == ["16: 0.5 %"]


def test_a_setting_named_in_its_section_is_an_input(tmp_path):
    page, folder = _site(tmp_path, "## Intervals\n\nEach parameter has a 95 % interval (`intervals.LEVEL`).\n\n"
                                   "## Elsewhere\n\nA 95 % interval; 0.06 above (`truths.ETA_SHIFT`).\n")
    assert _unbacked(page, folder) == ["7: 95 %"]


def test_results_doc_check_fails_on_an_unbacked_figure(tmp_path):
    doc = _load("results_doc")
    results = tmp_path / "validation" / "results"
    results.mkdir(parents=True)
    (results / "bench_pipeline.json").write_text(json.dumps(
        {"command": "mifaces measure", "runs": {"warm": {"wall_s": 97.8, "stages_s": {"total": 97.8}}}}))
    out = tmp_path / "docs" / "results.md"
    assert doc.main(["--results", str(results), "--out", str(out)]) == 0
    readme = tmp_path / "README.md"
    readme.write_text("# Demo\n\nThe main job takes 97.8 s (`bench_pipeline.json`).\n", encoding="utf-8")
    assert doc.main(["--results", str(results), "--out", str(out), "--check"]) == 0
    readme.write_text("# Demo\n\nThe main job takes 437 s (`bench_pipeline.json`).\n", encoding="utf-8")
    assert doc.main(["--results", str(results), "--out", str(out), "--check"]) == 1
