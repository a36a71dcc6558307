"""Light bounced between parts of the face, taken out of the reflectance samples.

A photograph of a face holds, besides the light that reached each point straight from the lamp,
light that reached it after bouncing off the face: the cheek lights the side of the nose, the
brow the eye's socket. The texture-space fit reads every pixel as direct light (paper eq. 4),
with one albedo per region. The bounced light is strongest in the concave parts and weakest on
the convex ones, where the highlights are: there the region's albedo, raised by the bounced light
the region averages, over-predicts the diffuse part, and the glossy lobe comes out too weak. On
simulated captures (path traced with up to three bounces) that made skin's ρ_s about 9 % low on
average (``docs/uncertainty.md``, ``validation/results/interreflection.json``).

:func:`bounced_light` renders each photograph's face with Mitsuba twice, with a first fit's
regions and albedo map, under the photograph's camera and light at a coarse resolution
(:data:`INDIRECT_WIDTH`: the bounced light is smooth): with the path tracer's depth
:data:`INDIRECT_DEPTH` and with direct light only (depth 2), the same random numbers, so that
the direct light cancels in their difference. The difference, blurred and brought to the
photograph's size, is the bounced light in each pixel; :func:`~mifaces.reflectance.resampling.capture_samples`
(``indirect=``) subtracts it before turning radiance into reflectance.
``fit_brdf(..., options=FitOptions(interreflection=True))`` fits, renders, samples again and fits
again, in the rounds :data:`INDIRECT_ROUNDS` lists
(:func:`mifaces.reflectance.sample_stage.without_bounced_light`).

**Two rounds, the second at the photograph's size.** The first fit's albedo still holds the
bounced light it is about to lose, so the light it renders bounced is too strong; and a coarse
render mixes a thin region's bounced light with its neighbours' (the lips', red, with the skin's
around them). Both over-correct the lips: with one coarse round their ρs came out 2–13 % high on
development captures. A second round, fitted on the samples the first corrected and rendered at
the photograph's own size, brought them within 2.5 % (and skin within 1.9 %): seeds 120, 124 and
128 of the coverage study's tuning seeds (``validation/results/interreflection_rounds.json``,
``python validation/interreflection_rounds.py``).
"""

from __future__ import annotations


import mitsuba as mi
import numpy as np
import scipy.ndimage

from ..runtime.progress import progress as progress_bar
from ..render.scene import FaceScene

#: The path tracer's depth of the render the bounced light is taken from (2 is direct light only):
#: light that bounced up to twice off the face before reaching the camera's point.
INDIRECT_DEPTH = 4
#: Width in pixels of the renders (at most the photograph's; the height follows the aspect) of the
#: first round, and its samples per pixel.
INDIRECT_WIDTH = 128
INDIRECT_SPP = 64
#: The rounds of :func:`~mifaces.reflectance.sample_stage.without_bounced_light`: (width, samples per
#: pixel) of each round's renders, None for the photograph's own width (module docstring).
INDIRECT_ROUNDS = ((INDIRECT_WIDTH, INDIRECT_SPP), (None, 16))
#: Standard deviation, in pixels of the renders, of the blur that takes their noise out.
INDIRECT_BLUR = 1.0


def coarse_camera(camera, width: int | None):
    """``camera`` with its image scaled to ``width`` pixels (at most its own; None: its own; same field
    of view and frame; pixel centres at integers, as :class:`~mifaces.capture.Camera` has them)."""
    return camera if width is None else camera.scaled(1.0 / max(1.0, camera.width / float(width)))


def _upsample(image: np.ndarray, small, camera) -> np.ndarray:
    """``image`` rendered by camera ``small`` at the pixels of ``camera`` (bilinear)."""
    fx, fy = small.width / camera.width, small.height / camera.height
    y, x = np.mgrid[0:camera.height, 0:camera.width].astype(np.float64)
    coords = [(y + 0.5) * fy - 0.5, (x + 0.5) * fx - 0.5]
    return np.stack([scipy.ndimage.map_coordinates(image[..., c], coords, order=1, mode="nearest")
                     for c in range(image.shape[-1])], axis=-1)


def bounced_light(capture, geometry, face_model, estimate, *, measurements=None, width: int | None = INDIRECT_WIDTH,
                  spp: int = INDIRECT_SPP, progress: bool = False) -> dict[str, np.ndarray]:
    """Per measurement, the (H, W, 3) radiance, in the photograph's units, that reached each pixel's
    point after bouncing off the face (module docstring): from renders of ``face_model`` at
    ``geometry[name]`` with the fitted ``estimate`` (a :class:`~mifaces.reflectance.result.BRDFEstimate`:
    its regions and albedo map, eq. 4's scale undone) under the measurement's camera and light."""
    undo = (np.pi / capture.reflectance_scale()).astype(np.float32)  # eq. 4's scale: albedo in the lights' units
    brdf, albedo = estimate.to_json(), estimate.albedo.albedo * undo
    chosen = [m for m in capture.measurements
              if m.name in geometry and (measurements is None or m.name in measurements)]
    out = {}
    for m in progress_bar(chosen, desc="interreflection", unit="photo", enabled=progress):
        camera = capture.camera_of(m)
        small = coarse_camera(camera, width)
        face = FaceScene(face_model, geometry[m.name])
        scene = face.cropped(face.scene(brdf, albedo, small, capture.light(m.light), spp=spp,
                                        max_depth=INDIRECT_DEPTH), small)
        direct_only = mi.load_dict({"type": "path", "max_depth": 2})  # the same scene loaded once, two integrators
        full, direct = (scene.render(spp, 0, integrator) for integrator in (scene.scene.integrator(), direct_only))
        bounced = np.clip(full - direct, 0.0, None)
        bounced = np.stack([scipy.ndimage.gaussian_filter(bounced[..., c], INDIRECT_BLUR) for c in range(3)], axis=-1)
        out[m.name] = (bounced if small is camera else _upsample(bounced, small, camera)).astype(np.float32)
    return out


__all__ = ["INDIRECT_DEPTH", "INDIRECT_WIDTH", "INDIRECT_SPP", "INDIRECT_ROUNDS", "INDIRECT_BLUR", "coarse_camera",
           "bounced_light"]
