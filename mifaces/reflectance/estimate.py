"""BRDF estimation from a capture: the stage from photographs and face
geometry to fitted BRDFs (paper sec. 4.3-5.3).

:func:`fit_brdf` chains the steps:

1. per measurement, the photograph resampled into the model's common texture
   parameterization and turned into weighted reflectance samples
   (:func:`mifaces.reflectance.resampling.capture_samples`: eq. 4, 9, 10, shadow
   and grazing-angle masks);
2. each sample labelled with the a-priori material region of its texel, as
   the triangle covering it is labelled
   (:func:`mifaces.model.regions.texel_regions_of_mesh`);
3. one BRDF model fitted per region by hierarchical Levenberg-Marquardt
   (:func:`mifaces.reflectance.fit.regions.fit_regions`; a region with too few samples
   borrows a neighbour's fit, a region with none is not evaluated);
4. optionally (``normals=True``, beyond the paper), a normal per texel
   alternated with step 3 (:func:`mifaces.reflectance.maps.normals.refine_texel_normals`);
5. the diffuse albedo refitted per texel with the glossy part fixed
   (:func:`mifaces.reflectance.maps.diffuse.refine_diffuse`).

With ``out`` (a folder, or a :class:`~mifaces.io.result_set.ResultTarget` that may replace a
result there), :func:`mifaces.reflectance.io.write_estimate` writes the result: ``brdf.json``, the
albedo map and ``scene.xml``.

The face geometry per measurement is an input: the simulator's ground truth
(``geometry="ground-truth"``), the shapes written by ``mifaces fit-shape``,
or any mapping from measurement name to world-space vertices.
"""

from __future__ import annotations

import os

from .. import brdf as brdf_models
from ..capture import load_capture
from ..io.result_set import ResultTarget
from ..shape.io import load_geometry
from .fitting import fit_samples
from .io import write_fitted
from .options import FitOptions, fit_options
from .result import BRDFEstimate
from .sample_stage import take_samples, with_balanced_lights, without_bounced_light
from .samples import ReflectanceSamples


def fit_brdf(capture, model: str = "cooktorrance", geometry="ground-truth", *, face_model=None,
             options: FitOptions | None = None, samples: ReflectanceSamples | None = None, measurements=None,
             out: str | os.PathLike | ResultTarget | None = None, progress: bool = True, **deprecated) -> BRDFEstimate:
    """Fit a BRDF model per region to the photographs of a capture: the samples stage
    (:func:`~mifaces.reflectance.sample_stage.take_samples`, then ``without_bounced_light`` and
    ``with_balanced_lights``), then :func:`~mifaces.reflectance.fitting.fit_samples`.

    Parameters
    ----------
    capture : Capture or path
    model : str
        ``phong``, ``cooktorrance``, ``ward`` or ``lafortune``.
    geometry : ``'ground-truth'``, path or mapping
        Per-measurement face geometry (:func:`~mifaces.shape.io.load_geometry`), with ``face_model``.
    options : FitOptions, optional
        How to fit; ``**deprecated``: its fields as keywords (a :class:`DeprecationWarning`).
    samples : ReflectanceSamples, optional
        Samples taken before, at ``options.resolution``; ``measurements``: fit these only.
    out : path or ResultTarget, optional
        Write the result there (:func:`~mifaces.reflectance.io.write_fitted`); a ``ResultTarget`` may replace one.

    Examples
    --------
    >>> from mifaces.reflectance import FitOptions, fit_brdf
    >>> estimate = fit_brdf(capture_folder, "phong", "ground-truth", options=FitOptions(resolution=32),
    ...                     out=out / "phong", progress=False)  # refine_estimate(estimate, ...) is next
    >>> sorted(estimate.fits["skin"].params), estimate.resolution, (out / "phong" / "brdf.json").is_file()
    (['diffuse_reflectance', 'exponent', 'specular_reflectance'], 32, True)
    """
    options = fit_options(options, deprecated, "fit_brdf")
    brdf = brdf_models.model(model, **options.brdf_options())
    face, shapes = load_geometry(capture := load_capture(capture), geometry, face_model)
    taken = take_samples(capture, shapes, face, options, samples=samples, measurements=measurements, progress=progress)
    taken = with_balanced_lights(without_bounced_light(taken, brdf, options, progress=progress), brdf, options)
    estimate = fit_samples(taken, brdf, options, progress=progress)
    if out is not None:
        target = ResultTarget.of(out)
        write_fitted(estimate, target.folder, taken.capture, face, shapes, force=target.force)
    return estimate


__all__ = ["fit_brdf"]
