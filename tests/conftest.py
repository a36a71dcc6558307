"""Shared test fixtures: the Mitsuba variants available on this machine."""

from __future__ import annotations

from pathlib import Path

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import drjit as dr
import numpy as np
import pytest

from mifaces.capture import Camera

REPO = Path(__file__).resolve().parents[1]

#: Variants the tests run in: scalar and LLVM always, CUDA where a GPU is present.
VARIANTS = ["scalar_rgb", "llvm_ad_rgb"] + (["cuda_ad_rgb"] if dr.has_backend(dr.JitBackend.CUDA) else [])
#: The vectorised (JIT) variants among them.
JIT_VARIANTS = [v for v in VARIANTS if v != "scalar_rgb"]
#: OpenCV axes looking down the world's -z: x right, y down, z forward.
FACING = np.diag([1.0, -1.0, -1.0])


def front_camera(focal: float = 500.0, rotation: np.ndarray = FACING) -> Camera:
    """A 48 x 64 camera 1.2 m in front of the model's face (world = model frame, mm), looking at it."""
    position = np.array([0.0, 0.0, 1200.0])
    return Camera(48, 64, focal, focal, 23.5, 31.5, np.zeros(5), rotation, -rotation @ position)


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
    and returns its folder; ``direct_only=True``: path depth 2, no light bounced off the face."""
    import mifaces.studio.scene as studio_scene
    from mifaces.studio import SimulationOptions, simulate

    def make(name: str, direct_only: bool = False, **options):
        mifaces.set_variant("llvm_ad_rgb")
        out = tmp_path_factory.mktemp(name) / "capture"
        default = studio_scene.INTEGRATOR
        if direct_only:
            studio_scene.INTEGRATOR = {**default, "max_depth": 2}
        try:
            simulate(out, SimulationOptions(**options), progress=False)
        finally:
            studio_scene.INTEGRATOR = default
        return out

    return make
