"""Shared test fixtures: the Mitsuba variants available on this machine."""

from __future__ import annotations

from pathlib import Path

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import drjit as dr
import pytest

REPO = Path(__file__).resolve().parents[1]

#: Variants the tests run in: scalar and LLVM always, CUDA where a GPU is present.
VARIANTS = ["scalar_rgb", "llvm_ad_rgb"] + (["cuda_ad_rgb"] if dr.has_backend(dr.JitBackend.CUDA) else [])
#: The vectorised (JIT) variants among them.
JIT_VARIANTS = [v for v in VARIANTS if v != "scalar_rgb"]


@pytest.fixture(params=VARIANTS)
def variant(request):
    """Run the test in every available variant."""
    mifaces.set_variant(request.param)
    yield request.param
    mifaces.set_variant(JIT_VARIANTS[0])


@pytest.fixture(params=JIT_VARIANTS)
def jit_variant(request):
    """Run the test in every available vectorised variant."""
    mifaces.set_variant(request.param)
    yield request.param


@pytest.fixture(scope="session")
def small_capture(tmp_path_factory):
    """A factory: ``small_capture(name, **options)`` simulates a small capture
    in the LLVM variant (:func:`mifaces.studio.simulate.simulate` with ``options``)
    and returns its folder."""
    from mifaces.studio.simulate import simulate

    def make(name: str, **options):
        mifaces.set_variant("llvm_ad_rgb")
        out = tmp_path_factory.mktemp(name) / "capture"
        simulate(out, progress=False, **options)
        return out

    return make
