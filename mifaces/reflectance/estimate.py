"""BRDF estimation from a capture: the stage from photographs and face
geometry to fitted BRDFs (paper sec. 4.3-5.3).

:func:`fit_brdf` chains the steps:

1. per measurement, the photograph resampled into the model's common texture
   parameterization and turned into weighted reflectance samples
   (:func:`mifaces.reflectance.samples.capture_samples`: eq. 4, 9, 10, shadow
   and grazing-angle masks);
2. each sample labelled with the a-priori material region of its texel, as
   the triangle covering it is labelled
   (:func:`mifaces.model.regions.texel_regions_of_mesh`);
3. one BRDF model fitted per region by hierarchical Levenberg-Marquardt
   (:func:`mifaces.reflectance.fitting.fit_regions`; a region with too few samples
   borrows a neighbour's fit, a region with none is not evaluated);
4. the diffuse albedo refitted per texel with the glossy part fixed
   (:func:`mifaces.reflectance.diffuse.refine_diffuse`).

:func:`write_estimate` writes the result atomically: ``brdf.json`` in the
layout of the simulator's ``--brdf-params`` (so a fitted BRDF can be put on
another face: ``mifaces simulate --brdf-params brdf.json``), with per region
the fit's loss, sample count, time and status under ``"fit"``; the albedo map
``albedo.exr`` (linear, row 0 at v = 0) and a PNG preview; and ``scene.xml``,
a Mitsuba scene that renders the fitted face with the plugins as the camera
saw it in the first measurement (meshes in ``meshes/``).

The face geometry per measurement is an input: the simulator's ground truth
(``geometry="ground-truth"``), the shapes written by ``mifaces fit-shape``,
or any mapping from measurement name to world-space vertices.
"""

from __future__ import annotations

import json
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import brdf as brdf_models
from .fitting import RegionFit, SubsetSchedule, fit_regions
from ..capture import GROUND_TRUTH, Capture, load_capture
from .diffuse import DiffuseMap, refine_diffuse
from ..files import atomic_path, atomic_write, write_exr, write_json, write_png
from ..model import MorphableModel, load_model
from ..model.regions import REGIONS, regions_present, texel_regions_of_mesh
from .samples import ReflectanceSamples, capture_samples
from ..geometry import load_geometry
from ..render import face_shapes
from ..status import PRIOR

#: Fit statistics stored per region under ``brdf.json``'s ``"fit"``.
FIT_KEYS = ("diffuse_reflectance", "loss", "samples", "seconds", "status", "reason", "iterations")


@dataclass
class BRDFEstimate:
    """Fitted BRDFs of one capture.

    Attributes
    ----------
    model : str
        Plugin name (``phong``, ``cooktorrance``, ``ward``, ``lafortune``).
    options : dict
        The model's options (e.g. ``{"lobes": 2}`` for Lafortune).
    fits : dict
        Region name -> :class:`~mifaces.reflectance.fitting.RegionFit`.
    albedo : DiffuseMap
        Per-texel diffuse albedo after refinement (sec. 5.3).
    region_map : (R, R) uint8
        Region label per texel of the albedo map.
    samples : int
        Reflectance samples used.
    measurements : tuple of str
    seconds : dict
        Wall time of each step: ``samples``, ``fit``, ``refine``, ``total``.
    """

    model: str
    options: dict
    fits: dict[str, RegionFit]
    albedo: DiffuseMap
    region_map: np.ndarray
    samples: int
    measurements: tuple[str, ...]
    seconds: dict = field(default_factory=dict)

    @property
    def resolution(self) -> int:
        return int(self.region_map.shape[0])

    def regions(self) -> dict[str, dict]:
        """Region -> the plugin's glossy parameters (no diffuse: that is the albedo map)."""
        return {name: {k: v for k, v in fit.params.items() if k != "diffuse_reflectance"}
                for name, fit in self.fits.items()}

    def to_json(self) -> dict:
        """The ``brdf.json`` document."""
        options = {k: v for k, v in self.options.items()}
        return {"model": self.model, "options": options, "regions": self.regions(),
                "fit": {name: {k: (fit.params.get(k) if k == "diffuse_reflectance" else getattr(fit, k))
                               for k in FIT_KEYS} for name, fit in self.fits.items()},
                "samples": int(self.samples), "resolution": self.resolution,
                "measurements": list(self.measurements), "seconds": {k: round(v, 3) for k, v in self.seconds.items()},
                "albedo": "albedo.exr"}


def fit_brdf(capture, model: str = "cooktorrance", geometry="ground-truth", *, face_model=None,
             resolution: int = 512, lobes: int = 1, options: dict | None = None, fixed: dict | None = None,
             schedule: SubsetSchedule | None = None, samples: ReflectanceSamples | None = None, measurements=None,
             out=None, seed: int = 0, progress: bool = True) -> BRDFEstimate:
    """Fit a BRDF model per region to the photographs of a capture.

    Parameters
    ----------
    capture : Capture or path
    model : str
        ``phong``, ``cooktorrance``, ``ward`` or ``lafortune``.
    geometry : ``'ground-truth'``, path or mapping
        Per-measurement face geometry (see :func:`load_geometry`).
    face_model : MorphableModel or path, optional
    resolution : int
        R of the R × R texture space (the paper used 1000).
    lobes : int
        Lafortune lobes.
    options : dict, optional
        Further model options (``fresnel=``, ``normalization=``, …).
    fixed : dict, optional
        Parameters held fixed in every region (default: the model's
        ``fixed_in_region``, e.g. Cook-Torrance's η at each region's published
        value, :data:`mifaces.brdf.materials.REFRACTIVE_INDEX`).
    schedule : SubsetSchedule, optional
        The LM subset hierarchy.
    samples : ReflectanceSamples, optional
        Samples computed before (skips step 1; must match ``resolution``).
    measurements : sequence of str, optional
        Fit to these measurements only (default: all with geometry).
    out : path, optional
        Write the result there (:func:`write_estimate`).

    Returns
    -------
    BRDFEstimate
    """
    t0 = time.perf_counter()
    capture = capture if isinstance(capture, Capture) else load_capture(capture)
    options = dict(options or {})
    if lobes != 1:
        options["lobes"] = int(lobes)  # brdf_models.model refuses it for a model with one lobe
    brdf = brdf_models.model(model, **options)
    face, shapes = load_geometry(capture, geometry, face_model)
    if samples is None:
        samples = capture_samples(capture, shapes, face, resolution, measurements=measurements, progress=progress)
    elif samples.resolution != resolution:
        raise ValueError(f"the samples are at resolution {samples.resolution}, not {resolution}")
    if len(samples) == 0:
        raise ValueError("no valid reflectance samples: every texel is hidden, shadowed, grazing or saturated")
    t_samples = time.perf_counter()
    region_map = texel_regions_of_mesh(face.region_map, face.uv, face.triangles, resolution)
    label = samples.label if samples.label is not None else samples.region(region_map)
    names = {REGIONS[n]: n for n in regions_present(face.region_map)}
    on_face = np.isin(label, list(names))
    light, view, r, sigma, texel, label = (a[on_face] for a in (samples.light, samples.view, samples.reflectance,
                                                                samples.sigma, samples.texel, label))
    # parameters with a published value per region (Cook-Torrance's η) are fixed at it unless given
    per_region = {name: {k: v for k, v in brdf.fixed_in_region(name).items() if fixed is None or k not in fixed}
                  for name in names.values()}
    fits = fit_regions(brdf, light, view, r, sigma, label, names, progress=progress, fixed=fixed,
                       fixed_by_region=per_region, schedule=schedule, seed=seed)
    t_fit = time.perf_counter()
    by_label = {REGIONS[name]: fit.params for name, fit in fits.items()}
    albedo = refine_diffuse(brdf, by_label, light, view, r, sigma, texel, label, region_map)
    t_end = time.perf_counter()
    estimate = BRDFEstimate(model=brdf.name, options=dict(options), fits=fits, albedo=albedo,
                            region_map=region_map, samples=int(on_face.sum()),
                            measurements=tuple(samples.measurement_names),
                            seconds={"samples": t_samples - t0, "fit": t_fit - t_samples, "refine": t_end - t_fit,
                                     "total": t_end - t0})
    if out is not None:
        first = next(m for m in capture.measurements if m.name == estimate.measurements[0])
        write_estimate(estimate, out, face, shapes[first.name], capture, first.light)
    return estimate


# --------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------
def _value(kind: str, value) -> ET.Element:
    if kind == "rgb":
        v = np.broadcast_to(np.asarray(value, np.float64), 3)
        return ET.Element("rgb", value=", ".join(f"{x:.9g}" for x in v))
    if kind == "string":
        return ET.Element("string", value=str(value))
    return ET.Element("float", value=f"{float(value):.9g}")


def scene_xml(estimate: BRDFEstimate, camera, light_position, intensity, meshes: dict[str, str],
              albedo: str = "albedo.exr", spp: int = 64) -> str:
    """A Mitsuba scene (XML text) of the fitted face: one ``ply`` shape per
    region with its fitted plugin BSDF over the albedo map, the capture's
    camera, a point light, and the path tracer (shadows, interreflection)."""
    from ..render import mitsuba_sensor

    model = brdf_models.model(estimate.model, **estimate.options)
    kinds = {p.name: p.kind for p in model.specular_parameters()}
    sensor = mitsuba_sensor(camera, spp)
    root = ET.Element("scene", version="3.0.0")
    ET.SubElement(root, "default", name="spp", value=str(spp))
    integrator = ET.SubElement(root, "integrator", type="path")
    ET.SubElement(integrator, "integer", name="max_depth", value="4")
    s = ET.SubElement(root, "sensor", type="perspective", id="camera")
    for key in ("fov", "principal_point_offset_x", "principal_point_offset_y", "near_clip", "far_clip"):
        ET.SubElement(s, "float", name=key, value=f"{sensor[key]:.9g}")
    ET.SubElement(s, "string", name="fov_axis", value=sensor["fov_axis"])
    matrix = np.asarray(sensor["to_world"].matrix, np.float64).reshape(4, 4)
    ET.SubElement(ET.SubElement(s, "transform", name="to_world"), "matrix",
                  value=" ".join(f"{x:.12g}" for x in matrix.ravel()))
    ET.SubElement(ET.SubElement(s, "sampler", type="independent"), "integer", name="sample_count", value="$spp")
    film = ET.SubElement(s, "film", type="hdrfilm")
    ET.SubElement(film, "integer", name="width", value=str(camera.width))
    ET.SubElement(film, "integer", name="height", value=str(camera.height))
    ET.SubElement(film, "string", name="pixel_format", value="rgb")
    ET.SubElement(ET.SubElement(film, "rfilter", type="gaussian"), "float", name="stddev", value="0.5")
    emitter = ET.SubElement(root, "emitter", type="point", id="light")
    ET.SubElement(emitter, "point", name="position", value=", ".join(f"{x:.9g}" for x in light_position))
    e = _value("rgb", intensity)
    e.set("name", "intensity")
    emitter.append(e)
    texture = ET.SubElement(root, "texture", type="bitmap", id="albedo")
    ET.SubElement(texture, "string", name="filename", value=albedo)
    ET.SubElement(texture, "boolean", name="raw", value="true")
    ET.SubElement(texture, "string", name="filter_type", value="bilinear")
    ET.SubElement(texture, "string", name="wrap_mode", value="clamp")
    regions = estimate.regions()
    for key, filename in meshes.items():
        name = key.removeprefix("face_").rsplit("_", 1)[0]  # face_<region>_<label>
        shape = ET.SubElement(root, "shape", type="ply", id=key)
        ET.SubElement(shape, "string", name="filename", value=filename)
        bsdf = ET.SubElement(shape, "bsdf", type=estimate.model)
        ET.SubElement(bsdf, "ref", id="albedo", name="diffuse_reflectance")
        for key, value in model.options.items():
            if key != "lobes":
                bsdf.append(ET.Element("string", name=key, value=str(value)))
        for key, value in regions[name].items():
            el = _value(kinds.get(key, "float"), value)
            el.set("name", key)
            bsdf.append(el)
    ET.indent(root, space="    ")
    header = ("<!-- The face as fitted by mifaces fit-brdf: per-region "
              f"{estimate.model} BSDFs over the refined albedo map, seen by the capture's camera under the light "
              "of its first measurement. Render: mitsuba.load_file(path, spp=N) after `import mifaces` "
              "(which registers the plugins). Units: mm. -->\n")
    return header + ET.tostring(root, encoding="unicode") + "\n"


def write_estimate(estimate: BRDFEstimate, out, face_model: MorphableModel, vertices: np.ndarray,
                   capture: Capture, light: str) -> dict[str, Path]:
    """Write ``brdf.json``, ``albedo.exr`` (+ ``albedo.png``), ``meshes/*.ply``
    and ``scene.xml`` into folder ``out``, each atomically; ``scene.xml``
    last, so a scene never names a file not yet written.

    ``vertices`` (world frame) is the geometry the scene shows, lit by the
    capture's light ``light``.
    """
    out = Path(out)
    paths = {"brdf": out / "brdf.json", "albedo": out / "albedo.exr", "preview": out / "albedo.png",
             "scene": out / "scene.xml"}
    write_json(paths["brdf"], estimate.to_json())
    write_exr(paths["albedo"], estimate.albedo.albedo)
    write_png(paths["preview"], estimate.albedo.albedo)
    meshes = {}
    for key, mesh in face_shapes(face_model, vertices, estimate.to_json()).items():
        rel = f"meshes/{key}.ply"
        with atomic_path(out / rel) as tmp:
            mesh.write_ply(str(tmp))
        meshes[key] = rel
    lamp = capture.light(light)
    text = scene_xml(estimate, capture.camera, lamp.position, lamp.intensity, meshes)
    with atomic_write(paths["scene"], "w") as f:
        f.write(text)
    return paths


def render_estimate(estimate: BRDFEstimate, face_model: MorphableModel, vertices: np.ndarray, camera,
                    light_position=None, intensity=None, envmap=None, envmap_scale: float = 1.0, spp: int = 64,
                    seed: int = 0) -> np.ndarray:
    """Render the fitted face (linear RGB, (H, W, 3)) on geometry ``vertices``
    (world frame) seen by ``camera``, under a point light and/or an
    environment map, with Mitsuba's path tracer as the simulator renders
    photographs (:func:`mifaces.render.render_face`): for novel poses, novel
    lights and comparisons with held-out photographs."""
    from ..render import render_face

    return render_face(estimate.to_json(), estimate.albedo.albedo, face_model, vertices, camera, light_position,
                       intensity, envmap, envmap_scale, spp, seed)


def render_fitted(brdf_dir, capture, out, measurement: str | None = None, geometry="ground-truth",
                  face_model=None, yaw: float = 0.0, light_position=None, envmap=None, envmap_scale: float = 1.0,
                  spp: int = 64) -> dict[str, Path]:
    """Render a fitted BRDF (a ``fit-brdf`` output folder) on a face of a capture,
    in a novel pose and light, and write ``out``.exr / .png.

    The BRDF may come from another face than the geometry: both share the
    model's texture parameterization, so the albedo map and the regions move
    with it (paper sec. 6). ``yaw`` turns the face about its vertical axis
    (degrees, about its centre); the light is the measurement's point light
    unless ``light_position`` (world, mm) or an ``envmap`` is given.
    """
    from ..render import render_face, save_image

    capture = capture if isinstance(capture, Capture) else load_capture(capture)
    data = load_estimate(brdf_dir)
    if data["albedo"] is None:
        raise FileNotFoundError(f"{brdf_dir}: no albedo map beside brdf.json")
    face, shapes = load_geometry(capture, geometry, face_model)
    name = measurement or next(m.name for m in capture.measurements if m.name in shapes)
    if name not in shapes:
        raise ValueError(f"no geometry for measurement {name!r}; have {sorted(shapes)}")
    albedo = data["albedo"]
    if albedo.ndim != 3 or albedo.shape[0] != albedo.shape[1]:
        raise ValueError(f"{brdf_dir}: the albedo map must be a square RGB image, got shape {albedo.shape}")
    vertices = np.asarray(shapes[name], np.float64)
    if yaw:
        from scipy.spatial.transform import Rotation

        up = -capture.camera.rotation[1]  # the camera's up direction in the world frame
        centre = vertices.mean(axis=0)
        vertices = Rotation.from_rotvec(np.radians(yaw) * up).apply(vertices - centre) + centre
    lamp = capture.light(next(m.light for m in capture.measurements if m.name == name))
    if light_position is None and envmap is None:
        light_position = lamp.position
    image = render_face(data, albedo, face, vertices, capture.camera, light_position,
                        None if light_position is None else lamp.intensity, envmap, envmap_scale, spp)
    return save_image(image, out)


def load_estimate(path) -> dict:
    """Read a ``brdf.json`` (path to it or its folder) and the albedo map beside it:
    the JSON document with ``"albedo"`` replaced by the (R, R, 3) array."""
    from ..files import read_exr

    path = Path(path)
    path = path / "brdf.json" if path.is_dir() else path
    if not path.is_file():
        raise FileNotFoundError(f"no brdf.json at {path}")
    data = json.loads(path.read_text())
    for key in ("model", "regions"):
        if key not in data:
            raise ValueError(f"{path}: not a brdf.json, no {key!r}")
    albedo = path.parent / data.get("albedo", "albedo.exr")
    data["albedo"] = read_exr(albedo) if albedo.is_file() else None
    return data


__all__ = ["BRDFEstimate", "fit_brdf", "write_estimate", "scene_xml", "render_estimate", "render_fitted",
           "load_estimate"]
