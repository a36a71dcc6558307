"""The Examples sections of the public API's docstrings run as doctests, as scikit-image's do:
each is code a user can paste, and the suite fails when one stops doing what it shows."""

from __future__ import annotations

import doctest
import importlib
import io

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import pytest

#: The public API whose docstrings carry an Examples section.
PUBLIC = ("mifaces.capture.load_capture", "mifaces.studio.simulate", "mifaces.shape.fit_shape",
          "mifaces.reflectance.fit_brdf", "mifaces.pipeline.measure.measure", "mifaces.render.FaceScene.render")


def public_object(path: str):
    """The function or method named by a dotted path (a module, then attributes)."""
    parts = path.split(".")
    for k in range(len(parts) - 1, 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError:
            continue
        for name in parts[k:]:
            obj = getattr(obj, name)
        return obj
    raise ValueError(path)


@pytest.fixture(scope="module")
def capture_folder(small_capture):
    """The examples' ``capture_folder``: a small simulated capture."""
    return small_capture("doctests", measurements=2, resolution=(96, 96), spp=4, albedo_resolution=128, seed=3)


@pytest.mark.parametrize("path", PUBLIC)
def test_docstring_examples_run(path, tmp_path, capture_folder):
    mifaces.set_variant("llvm_ad_rgb")
    obj = public_object(path)
    tests = doctest.DocTestFinder(recurse=False).find(obj, path, globs={"out": tmp_path,
                                                                        "capture_folder": capture_folder})
    examples = [e for t in tests for e in t.examples]
    assert "Examples\n" in (obj.__doc__ or ""), f"{path}'s docstring has no Examples section"
    assert sum(not e.options.get(doctest.SKIP) for e in examples) >= 2, f"{path}: fewer than two examples run"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report = io.StringIO()
    for test in tests:
        runner.run(test, out=report.write)
    assert runner.failures == 0, report.getvalue()
