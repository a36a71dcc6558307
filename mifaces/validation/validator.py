"""Validation of fitted BRDFs against a simulated capture's ground truth, in
measures that separate the models: BRDF error over the hemisphere, albedo
error, and image error of the face in a novel pose under lights and
environments the fit never saw.

Four numbers per fitted model (:meth:`Validator.validate`):

``brdf_rmse`` (per region)
    The BRDF error over the hemisphere, relative to the truth's RMS
    (:func:`mifaces.validation.brdf_error.brdf_rmse`, whose module says how).
``albedo_rmse``
    RMSE of the fitted albedo map against the truth's (resized to the fit's
    resolution), on texels with samples (linear reflectance units;
    :func:`mifaces.validation.truth_errors.ground_truth_errors`).
``heldout_rmse``
    Image error under :data:`~mifaces.validation.held_out.HELD_OUT_LIGHTS`
    point lights none of the photographs used
    (:func:`~mifaces.validation.held_out.held_out_lights`), in a novel pose
    (:data:`~mifaces.validation.held_out.NOVEL_POSE`,
    :func:`~mifaces.validation.held_out.novel_rotation`): the true face (true shape
    from the ground truth, true BSDF, true albedo) and the fitted face
    (fitted shape, fitted BRDF, fitted albedo) rendered by the same camera,
    cropped to the face (:func:`face_camera`, :data:`RENDER_SIZE`,
    :data:`SPP`); per image the relative RMSE on the face mask (pixels
    either face covers)::

        e = sqrt(mean (I_fit − I_true)²) / mean I_true

    and over the lights the root mean square of the e's.
``environment_rmse``
    The same under the generated studio and a sunsky
    (:mod:`mifaces.lights.environment`).

Renders are Monte Carlo estimates. The truth and every fit are rendered
with the same seed (common random numbers: the same camera rays and light
samples), so that the noise of the two images largely cancels in their
difference and what remains is the difference of the faces. The error a
perfect reflectance fit would still show is that of the fitted *shape*: the
true BSDF and albedo rendered on the fitted face (``shape_floor`` of
:attr:`Validator.summary`; 0 where the fit used the true shape, None where
the fitted face model's texture space is not the truth's). With fitted
shapes that floor dominates the image errors (pixels of a face a few mm
off), so each fit is also rendered on the true shape
(``heldout_rmse_true_shape``, ``environment_rmse_true_shape``): the error
of its reflectance alone, which separates the models.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial.transform import Rotation
from skimage.transform import resize

from ..capture import Camera, read_ground_truth
from ..lights.emitters import light_record
from ..lights.environment import LUMINANCE, SKY_SUN_ANGLES, Environment, sky_emitter, studio_environment
from ..render.face_pixels import front_of_face_pixels
from ..shape.io import load_geometry
from ..model.geometry import turned
from ..model.regions import REGIONS
from ..render import ALBEDO, FaceScene
from ..studio import subsurface as translucent
from ..studio.photograph import albedo_texture
from ..studio.simulate import true_face_meshes
from ..studio.varying import map_textures
from .brdf_error import brdf_rmse, region_texels
from .held_out import HELD_OUT_LIGHTS, NOVEL_POSE, held_out_lights, novel_rotation, true_lights
from .truth_errors import ground_truth_errors

#: Longer side of the face crop rendered (pixels), and samples per pixel.
RENDER_SIZE = 112
SPP = 16
#: Seed of every validation render (common random numbers, module docstring).
SEED = 101
#: Seed of the second render of the truth that measures the renders' Monte Carlo noise (``noise_floor``).
NOISE_SEED = 202
#: Suffix of the image errors of the fitted reflectance on the true shape.
TRUE_SHAPE = "_true_shape"


# --------------------------------------------------------------------------------------------
# The novel view: the camera's crop
# --------------------------------------------------------------------------------------------
def face_camera(camera, vertices: np.ndarray, size: int = RENDER_SIZE, margin: float = 0.1) -> Camera:
    """``camera`` cropped to the box around the projected ``vertices`` (with
    ``margin`` of its size around) and scaled so that its longer side is
    ``size`` pixels; same pose, no lens distortion (renders compared with
    each other, not with photographs)."""
    xy = camera.project(vertices)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = margin * (hi - lo)
    lo, hi = lo - pad, hi + pad
    scale = size / float(max(hi - lo))
    width, height = (max(8, int(round(s * scale))) for s in hi - lo)
    # the crop's left and top edges at lo (the camera's pixel coordinates, centres at integers)
    return Camera(width, height, camera.fx * scale, camera.fy * scale, (camera.cx - lo[0]) * scale - 0.5,
                  (camera.cy - lo[1]) * scale - 0.5, np.zeros(0), camera.rotation, camera.translation)


def relative_rmse(image: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    """sqrt(mean (image − truth)²) / mean truth over the pixels of ``mask`` and the channels."""
    error = np.asarray(image, np.float64)[mask] - np.asarray(truth, np.float64)[mask]
    return float(np.sqrt(np.mean(error ** 2)) / max(float(np.mean(np.asarray(truth, np.float64)[mask])), 1e-12))


def pose_angle(a: np.ndarray, b: np.ndarray) -> float:
    """The angle (degrees) of the rotation between two rotations (3x3)."""
    return float(np.degrees(Rotation.from_matrix(np.asarray(a) @ np.asarray(b).T).magnitude()))


# --------------------------------------------------------------------------------------------
# The truth rendered once, every fit compared with it
# --------------------------------------------------------------------------------------------
class Validator:
    """A simulated capture's true face, rendered once in a novel pose under
    held-out lights and environments, against which every fitted model is
    measured (:meth:`validate`; the measures are in the module docstring).

    Parameters
    ----------
    capture : Capture
        A simulated capture (with ``ground_truth/``).
    face_model : MorphableModel
        The model of the fitted shape.
    fit_vertices : (V, 3) array
        The fitted face of ``measurement`` (world, mm).
    measurement : str
        The measurement whose true and fitted faces are turned into the novel pose.
    size, spp : int
        Longer side of the rendered face crop (pixels), samples per pixel.
    pose : (yaw, pitch)
        The novel pose, degrees (:func:`novel_rotation`).
    lights : int
        Number of held-out point lights (:func:`held_out_lights`).
    environments : dict, optional
        Name -> environment (an equirectangular map or an emitter dict, the source of a
        :class:`mifaces.lights.environment.Environment`); default the
        generated studio and a sunsky with the sun at :data:`SKY_SUN_ANGLES`.

    Attributes
    ----------
    conditions : dict
        Name -> the light keyword arguments of :meth:`FaceScene.render`: ``{'light': Light}`` for a
        held-out light (:func:`held_out_lights`), ``{'environment': Environment}`` for an environment
        (:class:`mifaces.lights.environment.Environment`).
    truth : dict
        Name -> the true face's image (H, W, 3).
    mask, truth_mask : (H, W) bool
        The pixels compared: where the front of either face is seen; where the true face's is
        (:func:`mifaces.render.face_pixels.front_of_face_pixels`).
    summary : dict
        What was compared, for the report (pose, lights, environments, shape floor, sizes, seconds).
    """

    def __init__(self, capture, face_model, fit_vertices: np.ndarray, measurement: str, *, size: int = RENDER_SIZE,
                 spp: int = SPP, pose=NOVEL_POSE, lights: int = HELD_OUT_LIGHTS, environments: dict | None = None):
        t = time.perf_counter()
        if (environments is not None and not environments) or lights < 1:
            raise ValueError("a validation needs at least one environment and one held-out light")
        self.capture = capture
        self._albedo = {}  # the true albedo map at each fit resolution
        self.ground_truth = read_ground_truth(capture)
        if self.ground_truth is None:
            raise ValueError(f"{capture.path}: only a simulated capture (with ground truth) can be validated")
        self._truth_maps = map_textures(self.ground_truth.maps) or None  # a spatially varying truth's textures
        truth_model, true_shapes = load_geometry(capture, "ground-truth")
        true_vertices = true_shapes[measurement]
        centre = true_vertices.mean(axis=0)
        rotation = novel_rotation(capture.camera, pose)
        self.truth_scene = FaceScene(truth_model, turned(true_vertices, rotation, centre))
        self.fit_scene = FaceScene(face_model, turned(fit_vertices, rotation, centre))
        self.camera = face_camera(capture.camera, turned(true_vertices, rotation, centre), size)
        self.spp = int(spp)
        held_out = held_out_lights(true_lights(capture, self.ground_truth), centre, lights)
        self.conditions = {f"light_{k + 1}": {"light": light} for k, (light, _) in enumerate(held_out)}
        if environments is None:
            environments = {"studio": studio_environment(), "sky": sky_emitter(self.camera)}
        self.environments = tuple(environments)
        self.conditions.update({name: {"environment": Environment(value)} for name, value in environments.items()})
        self.truth_mask = front_of_face_pixels(truth_model, turned(true_vertices, rotation, centre), self.camera)
        self.mask = self.truth_mask | front_of_face_pixels(face_model, turned(fit_vertices, rotation, centre),
                                                           self.camera)
        truth = self.ground_truth.brdf
        true_meshes = self._true_face(truth_model, self.truth_scene, turned(true_vertices, rotation, centre))
        # the Monte Carlo noise of these renders: the truth against itself rendered with another seed; every
        # fit is compared with that second render too (``replicate``), which tells a ranking's ties
        renders = {name: self._render_truth(true_meshes, light, (SEED, NOISE_SEED))
                   for name, light in self.conditions.items()}
        self.truth = {name: images[0] for name, images in renders.items()}
        self.truth_replicate = {name: images[1] for name, images in renders.items()}
        noise = {name: relative_rmse(self.truth_replicate[name], self.truth[name], self.truth_mask)
                 for name in self.conditions}
        floor = self._shape_floor(truth_model, face_model, true_vertices, fit_vertices, rotation, centre)
        # where the shapes differ but share a texture space, the fitted reflectance is also judged on the true shape
        self._true_shape = None if floor is None else any(v > 0 for v in floor.values())
        first = next(m for m in self.ground_truth.measurements if m.name == measurement)
        novel = rotation @ first.rotation
        self.summary = {
            "truth_model": truth["model"], "measurement": measurement, "novel_pose": list(pose),
            "novel_pose_angle_to_capture": min(pose_angle(novel, m.rotation) for m in self.ground_truth.measurements),
            "held_out_lights": [{**light_record(light), "angle_to_capture": angle} for light, angle in held_out],
            "environments": [name for name in environments], "sky_sun_angles": list(SKY_SUN_ANGLES),
            "render": {"width": self.camera.width, "height": self.camera.height, "spp": self.spp,
                       "mask_pixels": int(self.mask.sum())},
            "shape_floor": None if floor is None else {**self._pooled(floor), "per_condition": floor},
            "noise_floor": {**self._pooled(noise), "per_condition": noise},
            "seconds": time.perf_counter() - t}

    def _true_face(self, face_model, scene: FaceScene, vertices: np.ndarray) -> dict:
        """The true reflectance on ``vertices`` as the simulator photographed it
        (:func:`mifaces.studio.simulate.true_face_meshes`): parameter maps of a
        spatially varying truth, translucent skin of a subsurface one."""
        truth = self.ground_truth
        meshes = true_face_meshes(face_model, np.asarray(vertices, np.float32), truth.brdf,
                                  albedo_texture(truth.albedo), map_textures(truth.maps), self._subsurface)
        return {key: meshes[key] for key in scene.meshes}  # keyed as the scene's meshes

    @property
    def _subsurface(self) -> bool:
        return "subsurface" in self.ground_truth.description

    def _render_truth(self, meshes: dict, light: dict, seeds=(SEED,)) -> list[np.ndarray]:
        """Images of the true face ``meshes`` (:meth:`_true_face`) under condition ``light``, one per Monte
        Carlo seed of ``seeds`` (the scene loaded once): the validation's camera and emitters, the
        simulator's integrator for a translucent truth."""
        scene = self.truth_scene.description(self.ground_truth.brdf, self.camera, spp=self.spp, **light)
        for key in (ALBEDO, *self.truth_scene.meshes):
            scene.pop(key)
        scene.update(meshes)
        if self._subsurface:
            scene["integrator"] = translucent.INTEGRATOR
        scene = self.truth_scene.cropped(scene, self.camera)
        return [scene.render(self.spp, seed) for seed in seeds]

    def _shape_floor(self, truth_model, face_model, true_vertices, fit_vertices, rotation, centre) -> dict | None:
        """Per condition, the error of the true reflectance on the fitted
        face: 0 without rendering where the fitted face is the true one, None
        where the two face models do not share a texture space."""
        if not (np.array_equal(truth_model.uv, face_model.uv) and
                np.array_equal(truth_model.triangles, face_model.triangles)):
            return None
        if np.array_equal(np.asarray(true_vertices, np.float64), np.asarray(fit_vertices, np.float64)):
            return {name: 0.0 for name in self.conditions}
        meshes = self._true_face(face_model, self.fit_scene, turned(fit_vertices, rotation, centre))
        return {name: relative_rmse(self._render_truth(meshes, light)[0], self.truth[name], self.mask)
                for name, light in self.conditions.items()}

    def _pooled(self, per_condition: dict) -> dict:
        """``heldout_rmse`` and ``environment_rmse`` pooled (root mean square) from per-condition errors."""
        lights = [v for k, v in per_condition.items() if k not in self.environments]
        environments = [v for k, v in per_condition.items() if k in self.environments]
        return {"heldout_rmse": float(np.sqrt(np.mean(np.square(lights)))),
                "environment_rmse": float(np.sqrt(np.mean(np.square(environments))))}

    def reflectance_scale(self, estimate, true_albedo: np.ndarray) -> float:
        """1 for a capture whose reflectance is absolute; for one measured under estimated lights
        (``brdf.json``'s ``lighting``: light intensity and albedo scale cannot be told apart) the
        factor that puts it in the truth's units: the median ratio of the true to the fitted
        albedo's luminance over the skin texels with samples, as a colour chart of known albedo
        would give it. The BRDF and albedo errors and the renders are compared after that factor."""
        if getattr(estimate, "lighting", None) is None:
            return 1.0
        skin = (estimate.region_map == REGIONS["skin"]) & (estimate.albedo.samples > 0)
        fitted = estimate.albedo.albedo[skin] @ LUMINANCE
        ok = fitted > 1e-6
        return float(np.median(true_albedo[skin][ok] @ LUMINANCE / fitted[ok])) if ok.any() else 1.0

    def validate(self, estimate) -> tuple[dict, dict]:
        """The measures of one fitted model (module docstring) and its images.

        Returns
        -------
        entry : dict
            ``brdf_rmse`` {region: float}, ``albedo_rmse``, ``heldout_rmse``,
            ``environment_rmse``, the per-condition errors
            (``per_condition``) and ``seconds``; where the fitted face
            model shares the truth's texture space, also
            ``heldout_rmse_true_shape``, ``environment_rmse_true_shape`` and
            ``per_condition_true_shape``: the fitted BRDF and albedo
            rendered on the *true* shape (the reflectance alone; equal to
            the others where the fit used the true shape). ``replicate``: the same pooled image
            errors with every render's random numbers drawn again (:data:`NOISE_SEED`), so that
            two models' difference can be told from Monte Carlo noise (:func:`mifaces.report.measurement.ties`).
        images : dict
            Condition name -> the fitted face's image (H, W, 3).
        """
        t = time.perf_counter()
        fit, albedo = estimate.to_json(), estimate.albedo.albedo
        maps = {"normals": estimate.normal_texture(), "specular": estimate.specular_texture()}
        r = estimate.resolution
        if r not in self._albedo:
            self._albedo[r] = resize(self.ground_truth.albedo, (r, r, 3), anti_aliasing=True, order=1)
        true_albedo = self._albedo[r]
        scale = self.reflectance_scale(estimate, true_albedo)
        regions = {}
        for name in estimate.fits:
            texels = estimate.region_map == REGIONS[name]
            uv = region_texels(estimate.region_map, REGIONS[name])
            if len(uv):
                regions[name] = brdf_rmse(self.ground_truth.brdf, fit, name, true_albedo[texels].mean(axis=0),
                                          albedo[texels].mean(axis=0), uv, truth_maps=self._truth_maps,
                                          scale=scale)
        errors = ground_truth_errors(estimate, self.capture, self.ground_truth, albedo_scale=scale)
        images, per_condition, replicate = {}, {}, {}

        def error(scene, name, light, mask):
            """The image at :data:`SEED`, its error and the error of the image at :data:`NOISE_SEED`
            (against the truth's replicate), from one loaded scene."""
            image, again = (scale * im for im in scene.render_seeds(fit, albedo, self.camera, spp=self.spp,
                                                                      seeds=(SEED, NOISE_SEED), **light, **maps))
            return image, relative_rmse(image, self.truth[name], mask), relative_rmse(again,
                                                                                    self.truth_replicate[name], mask)

        for name, light in self.conditions.items():
            images[name], per_condition[name], replicate[name] = error(self.fit_scene, name, light, self.mask)
        entry = {"brdf_rmse": regions, "albedo_rmse": errors["albedo"]["rmse_sampled"], **self._pooled(per_condition),
                 "per_condition": per_condition, "reflectance_scale": scale, "replicate": self._pooled(replicate)}
        if self._true_shape is not None:
            on_truth, again = per_condition, replicate
            if self._true_shape:
                both = {name: error(self.truth_scene, name, light, self.truth_mask)[1:]
                        for name, light in self.conditions.items()}
                on_truth = {name: errors[0] for name, errors in both.items()}
                again = {name: errors[1] for name, errors in both.items()}
            entry.update({f"{k}{TRUE_SHAPE}": v for k, v in self._pooled(on_truth).items()})
            entry[f"per_condition{TRUE_SHAPE}"] = on_truth
            entry["replicate"].update({f"{k}{TRUE_SHAPE}": v for k, v in self._pooled(again).items()})
        entry["seconds"] = time.perf_counter() - t
        return entry, images


__all__ = ["RENDER_SIZE", "SPP", "SEED", "NOISE_SEED", "TRUE_SHAPE", "face_camera", "relative_rmse", "pose_angle",
           "Validator"]
