"""mifaces.render: one face-scene description, loaded in memory and written as Mitsuba XML."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import mitsuba as mi
import numpy as np
import pytest

from mifaces.capture import Camera, Light
from mifaces.io.image_files import write_exr
from mifaces.model import load_model
from mifaces.brdf.model import rgb
from mifaces.render import ALBEDO, ALBEDO_REF, FaceScene, region_meshes, scene_xml

from conftest import front_camera

SPP_PATH = ("sensor", "sampler", "sample_count")


def small_scene(texture_file) -> dict:
    """A sphere in a plugin BSDF over a bitmap texture referenced by id, a point light."""
    mifaces.set_variant("llvm_ad_rgb")
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 3, "hide_emitters": False},
            "sensor": {"type": "perspective", "fov": 40.0,
                       "to_world": mi.ScalarTransform4f().look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": 24, "height": 16, "pixel_format": "rgb",
                                "rfilter": {"type": "gaussian", "stddev": 0.5}},
                       "sampler": {"type": "independent", "sample_count": 3}},
            "tex": {"type": "bitmap", "filename": str(texture_file), "raw": True, "filter_type": "bilinear"},
            "ball": {"type": "sphere", "center": [0.0, 0.1, 0.0], "radius": 1.0,
                     "bsdf": {"type": "cooktorrance", "diffuse_reflectance": {"type": "ref", "id": "tex"},
                              "specular_reflectance": rgb([0.2, 0.3, 0.4]), "roughness": 0.45, "eta": 1.4}},
            "light": {"type": "point", "position": [2.0, 3.0, 4.0], "intensity": rgb(30.0)}}


def test_scene_xml_renders_as_the_dict(tmp_path):
    texture = tmp_path / "tex.exr"
    write_exr(texture, np.linspace(0.1, 0.9, 8 * 8 * 3, dtype=np.float32).reshape(8, 8, 3))
    scene = small_scene(texture)
    path = tmp_path / "scene.xml"
    path.write_text(scene_xml(scene, {"spp": SPP_PATH}, comment="a sphere"))
    from_file = np.array(mi.render(mi.load_file(str(path)), seed=2))
    from_dict = np.array(mi.render(mi.load_dict(scene), seed=2))
    assert from_dict.shape == (16, 24, 3) and from_dict.max() > 0
    np.testing.assert_allclose(from_file, from_dict, rtol=1e-5, atol=1e-6)
    # the sample count is a parameter of the file, with the dict's value as its default
    assert mi.load_file(str(path)).sensors()[0].sampler().sample_count() == 3
    assert mi.load_file(str(path), spp=7).sensors()[0].sampler().sample_count() == 7
    assert path.read_text().startswith("<!-- a sphere -->")


def test_scene_xml_refuses_what_it_cannot_write(tmp_path):
    scene = small_scene(tmp_path / "tex.exr")
    scene["tex"] = {"type": "bitmap", "bitmap": mi.Bitmap(np.ones((2, 2, 3), np.float32))}
    with pytest.raises(TypeError, match=r"tex\.bitmap: a Bitmap has no Mitsuba XML form"):
        scene_xml(scene)
    with pytest.raises(ValueError, match="not a scene dict"):
        scene_xml(scene["ball"])


@pytest.fixture(scope="module")
def face():
    mifaces.set_variant("llvm_ad_rgb")
    model = load_model()
    return model, FaceScene(model, model.shape_mean)


def test_region_meshes_cover_the_face_once(face):
    model, scene = face
    meshes = region_meshes(model, model.shape_mean)
    assert list(meshes) == list(scene.meshes) and "face_skin_1" in meshes
    assert sum(len(m.triangles) for m in meshes.values()) == len(model.triangles)
    for key, part in meshes.items():
        assert key.startswith(f"face_{part.region}_")
        assert part.vertices.shape == part.normals.shape and len(part.uv) == len(part.vertices)
        assert part.triangles.max() == len(part.vertices) - 1


def test_region_of_key_names_a_traversed_parameters_region(face):
    _, scene = face
    shapes = {key: part.mesh({"type": "diffuse"}) for key, part in scene.meshes.items()}
    params = mi.traverse(mi.load_dict({"type": "scene", **shapes}))
    bsdf_keys = [key for key in params.keys() if ".bsdf." in key]
    assert len(bsdf_keys) == len(scene.meshes)
    for key in params.keys():
        mesh = key.split(".")[0]
        expected = (scene.meshes[mesh].region, "reflectance.value") if key in bsdf_keys else None
        assert scene.region_of_key(key) == expected
    assert scene.region_of_key("environment.data") is None


def test_face_scene_description_names_files_and_loads_in_memory(face, tmp_path):
    model, scene = face
    brdf = {"model": "ward", "options": {}, "regions": {"skin": {"specular_reflectance": 0.05, "alpha": 0.3}}}
    lamp = Light("lamp", np.array([0.0, 300.0, 1000.0]), np.full(3, 1e6))
    description = scene.description(brdf, front_camera(), lamp, spp=2, albedo="a.exr")
    assert description[ALBEDO]["filename"] == "a.exr"
    for key in scene.meshes:
        assert description[key]["filename"] == FaceScene.mesh_file(key)
        assert description[key]["bsdf"]["diffuse_reflectance"] == ALBEDO_REF
        assert description[key]["bsdf"]["alpha"] == 0.3  # regions without parameters take skin's
    assert "environment" not in description
    albedo = np.full((16, 16, 3), 0.5, np.float32)
    loaded = scene.scene(brdf, albedo, front_camera(), lamp, spp=2)
    assert ALBEDO not in loaded and all(isinstance(loaded[key], mi.Mesh) for key in scene.meshes)
    # the written meshes are the ones in memory
    paths = scene.write_meshes(tmp_path)
    written = mi.load_dict({"type": "ply", "filename": str(paths["face_skin_1"])})
    np.testing.assert_array_equal(np.array(mi.traverse(written)["vertex_positions"]),
                                  np.array(mi.traverse(loaded["face_skin_1"])["vertex_positions"]))
    image = scene.render(brdf, albedo, front_camera(), lamp, spp=2)
    assert image.shape == (64, 48, 3) and (image.mean(axis=2) > 0).mean() > 0.2


def test_directional_light_lights_a_white_face_at_e_over_pi(face):
    """A directional light of irradiance E from the camera's side shows a white Lambertian face
    facing it as E/π (the photographs' units of a capture with relative intensities)."""
    model, scene = face
    brdf = {"model": "phong", "options": {}, "regions": {"skin": {"specular_reflectance": 0.0, "exponent": 10.0}}}
    towards = np.array([0.0, 0.0, 1.0])  # from the face to the camera
    description = scene.description(brdf, front_camera(), Light("sun", None, np.full(3, 2.0), direction=towards * 3), spp=2)
    assert description["light"] == {"type": "directional", "direction": [-0.0, -0.0, -1.0],
                                    "irradiance": rgb(2.0)}
    albedo = np.ones((16, 16, 3), np.float32)
    image = scene.render(brdf, albedo, front_camera(), Light("sun", None, np.full(3, 2.0), direction=towards), spp=16)
    centre = image[28:36, 20:28].mean(axis=(0, 1))  # the nose's neighbourhood faces the camera
    assert np.all(centre > 0.5 * 2.0 / np.pi) and np.all(centre <= 2.0 / np.pi * 1.02)
    with pytest.raises(ValueError, match="not both"):
        scene.description(brdf, front_camera(), Light("both", np.array([0.0, 0.0, 1000.0]), np.ones(3), direction=towards))
    with pytest.raises(ValueError, match="finite, non-zero"):
        scene.description(brdf, front_camera(), Light("zero", None, np.ones(3), direction=np.zeros(3)))
    with pytest.raises(ValueError, match="needs a light"):
        scene.description(brdf, front_camera(), None)


def test_render_seeds_gives_each_seeds_own_render_from_one_loaded_scene(face):
    """One scene loaded for several Monte Carlo seeds (the validation renders each condition twice)
    gives, per seed, the image a render of its own at that seed gives (to float32 rounding: the kernels
    Dr.Jit compiles for a scene's first and later renders may round differently); the seeds differ."""
    model, scene = face
    brdf = {"model": "phong", "options": {}, "regions": {"skin": {"specular_reflectance": 0.2, "exponent": 10.0}}}
    albedo = np.full((16, 16, 3), 0.5, np.float32)
    lamp = Light("lamp", np.array([100.0, 200.0, 600.0]), np.full(3, 2e5))
    both = scene.render_seeds(brdf, albedo, front_camera(), lamp, spp=2, seeds=(0, 5))
    for seed, image in zip((0, 5), both):
        np.testing.assert_allclose(image, scene.render(brdf, albedo, front_camera(), lamp, spp=2, seed=seed),
                                   rtol=1e-5, atol=1e-7)
    assert np.abs(both[0] - both[1]).max() > 100 * 1e-5 * np.abs(both[0]).max()


@pytest.mark.parametrize("cx, cy", [(20.0, 50.0), (49.5, 39.5), (70.0, 10.0)])
def test_sensor_puts_a_point_where_the_camera_projects_it(cx, cy):
    """An off-centre principal point: the render of a small sphere is centred where
    Camera.project puts its centre (Mitsuba's offsets have the opposite sign of OpenCV's)."""
    import mitsuba as mi

    from mifaces.render import mitsuba_sensor

    mifaces.set_variant("llvm_ad_rgb")
    camera = Camera(100, 80, 200.0, 200.0, cx, cy, np.zeros(0), np.diag([1.0, -1.0, -1.0]), np.array([0, 0, 1000.0]))
    point = np.array([[30.0, 20.0, 0.0]])
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "direct", "hide_emitters": True},
                          "sensor": mitsuba_sensor(camera, 16), "emitter": {"type": "constant"},
                          "ball": {"type": "sphere", "center": point[0].tolist(), "radius": 5.0}})
    rows, cols = np.nonzero(np.array(mi.render(scene))[..., 0] > 0.1)
    np.testing.assert_allclose([cols.mean(), rows.mean()], camera.project(point)[0], atol=0.5)
