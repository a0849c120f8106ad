"""Scenes built in Python: the same pixels as the scene file with the same contents,
instances with any invertible transform, errors that name the call, and checkpoints."""

import json
import pickle

import numpy as np
import pytest

import canopy_rt as canopy
from conftest import GLTF, MESHES

TEAPOT = MESHES / "teapot.obj"

SCENE_FILE = f"""
name = "table"
background = "sky"
[camera]
look_from = [0, 3, 9]
look_at = [0, 0.5, 0]
vfov = 35
[render]
width = 40
height = 30
spp = 3
max_depth = 5
seed = 11
[[spheres]]
center = [0, -100, 0]
radius = 99.5
material = {{ type = "lambertian", albedo = [0.5, 0.5, 0.5] }}
[[spheres]]
center = [2.2, 0.5, 0]
radius = 0.5
material = {{ type = "dielectric", ior = 1.5 }}
[[spheres]]
center = [0, 0.3, 2]
radius = 0.3
material = {{ type = "pbr", base_color = [0.9, 0.6, 0.2], metallic = 1, roughness = 0.4 }}
[[cuboids]]
min = [-0.5, -0.5, -0.5]
max = [0.5, 0.5, 0.5]
rotate = [0, 30, 0]
translate = [-2.2, 0, 0]
material = {{ type = "metal", albedo = [0.9, 0.8, 0.6], fuzz = 0.1 }}
[geometry.teapot]
file = "{TEAPOT}"
smooth = false
[[instances]]
geometry = "teapot"
material = {{ type = "lambertian", albedo = [0.8, 0.3, 0.2] }}
places = [{{ translate = [0, 0, 0] }}, {{ translate = [0, 0, -3] }}]
"""


def table_scene(look_from=(0, 3, 9), vfov=35, back=None) -> canopy.Scene:
    """The scene of SCENE_FILE built in Python (its second teapot placed by `back`,
    moved back by 3 unless given)."""
    scene = canopy.Scene(size=(40, 30), spp=3, max_depth=5, seed=11, name="table")
    scene.camera(look_from=look_from, look_at=(0, 0.5, 0), vfov=vfov)
    scene.add_sphere((0, -100, 0), 99.5, material=canopy.lambertian((0.5, 0.5, 0.5)))
    scene.add_sphere((2.2, 0.5, 0), 0.5, material=canopy.dielectric(1.5))
    scene.add_sphere((0, 0.3, 2), 0.3, material=canopy.pbr((0.9, 0.6, 0.2), metallic=1, roughness=0.4))
    scene.add_box((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5), rotate=(0, 30, 0), translate=(-2.2, 0, 0),
                  material=canopy.metal((0.9, 0.8, 0.6), fuzz=0.1))
    vertices, faces = canopy.load_mesh(TEAPOT)
    teapot = scene.add_mesh(vertices, faces, material=canopy.lambertian((0.8, 0.3, 0.2)))
    if back is None:
        back = np.eye(4)
        back[2, 3] = -3
    scene.add_instance(teapot, back)
    return scene


def test_a_python_scene_renders_the_scene_files_pixels(tmp_path):
    path = tmp_path / "table.toml"
    path.write_text(SCENE_FILE)
    from_file = canopy.render(str(path), allow_paths=[MESHES])
    scene = table_scene()
    info = scene.info()
    assert info.counts["primitives"] == 4 and info.counts["instances"] == 2
    assert info.counts["instanced_triangles"] == 2 * len(canopy.load_mesh(TEAPOT)[1])
    from_python = canopy.render(scene)
    assert from_python.shape == (30, 40, 3)
    assert from_python.max() > 0
    np.testing.assert_array_equal(from_python, from_file)
    # Overrides and regions apply to Python scenes as to files.
    part = canopy.render(scene, region=(5, 6, 10, 7))
    np.testing.assert_array_equal(part, from_python[6:13, 5:15])


def test_a_frame_moves_the_camera_and_instances_as_building_it_so_would():
    moved = np.eye(4)
    moved[:3, 3] = (1.5, 0.2, -1)
    scene = table_scene()
    frame = canopy.render(scene, camera={"look_from": (2, 3, 8), "vfov": 30}, instances={1: moved})
    again = table_scene(look_from=(2, 3, 8), vfov=30, back=moved)
    np.testing.assert_array_equal(frame, canopy.render(again))
    assert not np.array_equal(frame, canopy.render(scene))
    for kwargs, words in [({"camera": {"fov": 30}}, "no `fov`"),
                          ({"camera": {"look_from": (0, 0.5, 0)}}, "camera"),
                          ({"instances": {9: np.eye(4)}}, "instance 9 does not exist"),
                          ({"instances": {1: np.zeros((3, 4))}}, "invertible")]:
        with pytest.raises(ValueError, match=words):
            canopy.render(scene, **kwargs)


def test_a_scene_pickles_to_the_same_pixels(tmp_path):
    import pickle

    scene = table_scene()
    scene.background((0.2, 0.3, 0.4))
    copy = pickle.loads(pickle.dumps(scene))
    np.testing.assert_array_equal(canopy.render(copy), canopy.render(scene))
    # Refused calls are not part of the record: the copy has what the scene has.
    with pytest.raises(ValueError):
        scene.add_sphere((0, 0, 0), -1, material=canopy.lambertian((1, 1, 1)))
    assert pickle.loads(pickle.dumps(scene)).info().counts == scene.info().counts
    # A mesh added to the copy takes the material its mesh was added with.
    copy.add_instance(0, np.eye(4))
    assert copy.info().counts["instances"] == scene.info().counts["instances"] + 1


def test_contents_give_back_every_shape_material_and_the_camera():
    scene = table_scene()
    contents = scene.info().contents()
    assert contents["camera"]["look_from"] == [0, 3, 9] and contents["camera"]["vfov"] == 35
    assert contents["background"] == {"type": "sky"}
    materials = contents["materials"]
    spheres = contents["spheres"]
    np.testing.assert_array_equal(spheres["radii"], np.float32([99.5, 0.5, 0.3]))
    np.testing.assert_array_equal(spheres["centers"][1], np.float32([2.2, 0.5, 0]))
    assert materials[spheres["materials"][1]] == {"type": "dielectric", "ior": 1.5}
    glossy = materials[spheres["materials"][2]]
    assert glossy["type"] == "pbr" and glossy["metallic"] == 1
    # A material made from its own table is the same material.
    for m in materials:
        wo, wi = np.array([[0.0, 0.6, 0.8]]), np.array([[0.0, 0.8, 0.6]])
        np.testing.assert_array_equal(canopy.eval_material(m, wo, wi)[0],
                                      canopy.eval_material(dict(m), wo, wi)[0])
    boxes = contents["cuboids"]
    assert boxes["rotation"].shape == (1, 3, 3)
    corner = boxes["rotation"][0] @ boxes["max"][0] + boxes["translation"][0]
    turn = np.radians(30)
    np.testing.assert_allclose(corner, [-2.2 + 0.5 * np.cos(turn) + 0.5 * np.sin(turn), 0.5,
                                        0.5 * np.cos(turn) - 0.5 * np.sin(turn)], atol=1e-5)
    triangles = contents["triangles"]
    vertices, faces = canopy.load_mesh(TEAPOT)
    assert triangles["vertices"].shape == (2 * len(faces), 3, 3) and not triangles["smooth"].any()
    # The second instance is the mesh moved back by 3: its triangles in the world.
    np.testing.assert_allclose(triangles["vertices"][len(faces):], vertices[faces] - [0, 0, 3], atol=1e-5)
    assert {materials[m]["type"] for m in triangles["materials"]} == {"lambertian"}


def test_instances_take_any_invertible_transform_and_the_mesh_is_stored_once():
    scene = canopy.Scene(size=(24, 18), spp=2)
    scene.camera(look_from=(0, 0, 8), look_at=(0, 0, 0))
    vertices, faces = canopy.load_mesh(TEAPOT)
    teapot = scene.add_mesh(vertices, faces, smooth=True)
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    squash = np.diag([2.0, 0.5, 1.0, 1.0])
    squash[:3, 3] = (0, 2, 0)
    angle = np.radians(40)
    turn = np.array([[np.cos(angle), 0, np.sin(angle), -2], [0, 1, 0, -1], [-np.sin(angle), 0, np.cos(angle), 0]])
    for i, t in enumerate([mirror, squash, turn]):
        assert scene.add_instance(teapot, t, material=canopy.emissive((1, 1, 1)) if i == 2 else None) == i + 1
    info = scene.info()
    assert info.counts["instances"] == 4 and info.counts["emissive_materials"] == 1
    image = canopy.render(scene)
    assert np.isfinite(image).all() and image.max() > 0


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda s: s.add_sphere((0, 0, 0), -1, material=canopy.lambertian((1, 1, 1))), "add_sphere: `center`"),
        (lambda s: s.add_sphere((0, 0, 0), 1, material=canopy.lambertian((2, 1, 1))), "[0, 1]"),
        (lambda s: s.add_sphere((0, 0, 0), 1, material={"type": "lambertian", "albdo": [1, 1, 1]}), "has no `albdo`"),
        (lambda s: s.add_sphere((0, 0, 0), 1, material={"type": "plastic"}), "unknown type `plastic`"),
        (lambda s: s.add_sphere((0, 0, 0), 1, material=7), "material 7 does not exist"),
        (lambda s: s.add_sphere((0, 0, 0), 1, material=canopy.pbr((1, 1, 1), roughness=2)), "`roughness` must be in [0, 1]"),
        (lambda s: s.add_spheres([[0, 0, 0], [1, 0, 0]], [1, 0], material=canopy.dielectric(1.5)), "sphere 1"),
        (lambda s: s.add_box((1, 1, 1), (0, 0, 0), material=canopy.dielectric(1.5)), "`min`"),
        (lambda s: s.add_mesh([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]], [[0, 1, 2]]), "vertices[2]"),
        (lambda s: s.add_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]]), "faces[0]"),
        (lambda s: s.add_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], transform=np.zeros((4, 4))), "last row"),
        (lambda s: s.add_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], transform=np.zeros((3, 4))), "invertible"),
        (lambda s: s.add_instance(5), "mesh 5 does not exist"),
        (lambda s: s.camera(look_from=(0, 0, 0), look_at=(0, 0, 0)), "same point"),
        (lambda s: s.background("night"), "background must be"),
        (lambda s: s.background(environment="/no/such/sky.hdr"), "sky.hdr"),
        (lambda s: s.settings(size=(0, 4), spp=1), "settings"),
    ],
)
def test_a_refused_call_names_its_fault_and_changes_nothing(call, words):
    scene = canopy.Scene(size=(8, 8), spp=1)
    before = repr(scene)
    with pytest.raises(ValueError) as e:
        call(scene)
    assert words in str(e.value), str(e.value)
    assert repr(scene) == before


def test_a_python_scene_resumes_from_its_checkpoint(tmp_path):
    checkpoint = tmp_path / "table.checkpoint"
    scene = table_scene()
    whole = canopy.render(scene, spp=4)

    def stop(done, total):
        if done == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        canopy.render(scene, spp=4, checkpoint=checkpoint, progress=stop)
    resumed = canopy.render(scene, resume=checkpoint)
    np.testing.assert_array_equal(resumed, whole)
    # Another scene is not continued from it.
    with pytest.raises(KeyboardInterrupt):
        canopy.render(scene, spp=4, checkpoint=checkpoint, progress=stop)
    other = table_scene()
    other.add_sphere((0, 5, 0), 1, material=canopy.emissive((4, 4, 4)))
    with pytest.raises(ValueError, match="different scene"):
        canopy.render(other, resume=checkpoint)


def test_the_documented_examples_run():
    import doctest

    import canopy_rt.ray_scene
    import canopy_rt.scene

    for module in (canopy_rt.scene, canopy_rt.ray_scene):
        result = doctest.testmod(module)
        assert result.attempted > 0 and result.failed == 0, (module.__name__, result)


def test_instances_render_on_the_gpu_as_on_the_cpu():
    if not canopy.devices():
        pytest.skip("no GPU adapter (not even a software one)")
    scene = table_scene()
    cpu = canopy.render(scene, spp=8)
    gpu = canopy.render(scene, spp=8, device="gpu")
    # The same random streams through two-level traversal on both: close means, and
    # most pixels the same to rounding.
    assert abs(gpu.mean() - cpu.mean()) < 0.03 * cpu.mean()
    assert np.mean(np.isclose(gpu, cpu, rtol=1e-2, atol=1e-3)) > 0.8


def test_gltf_models_render_as_the_scene_file_places_them(tmp_path):
    truck = MESHES.parent / "gltf" / "CesiumMilkTruck.glb"
    path = tmp_path / "truck.toml"
    path.write_text(f"""
background = "sky"
camera = {{ look_from = [6, 3, 8], look_at = [0, 1, 0] }}
render = {{ width = 32, height = 24, spp = 2 }}
[[gltf]]
file = "{truck}"
rotate = [0, 30, 0]
""")
    from_file = canopy.render(str(path), allow_paths=[GLTF])
    scene = canopy.Scene(size=(32, 24), spp=2)
    scene.camera(look_from=(6, 3, 8), look_at=(0, 1, 0))
    turned = np.eye(4)
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    turned[[0, 0, 2, 2], [0, 2, 0, 2]] = [c, s, -s, c]
    placed = scene.add_gltf(truck, turned)
    assert placed == 5  # the truck's body parts and two wheels, sharing one mesh
    counts = scene.info().counts
    assert counts["images"] == 1 and counts["textured_materials"] >= 1, counts
    np.testing.assert_allclose(canopy.render(scene), from_file, atol=1e-6)
    # A refused model changes nothing.
    broken = tmp_path / "broken.glb"
    broken.write_bytes(b"glTF" + bytes(20))
    with pytest.raises(ValueError, match="add_gltf: `.*broken.glb`: not a valid glTF 2.0 file"):
        scene.add_gltf(broken)
    assert scene.info().counts["instances"] == 5


def test_materials_are_evaluated_in_the_surface_frame():
    rng = np.random.default_rng(4)
    wo, wi = rng.normal(size=(2, 500, 3))
    wo[:, 2], wi[:, 2] = np.abs(wo[:, 2]), np.abs(wi[:, 2])
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    value, pdf = canopy.eval_material(canopy.lambertian((0.5, 0.25, 1.0)), wo, wi)
    np.testing.assert_allclose(value, np.outer(wi[:, 2] / np.pi, [0.5, 0.25, 1.0]), rtol=1e-5)
    np.testing.assert_allclose(pdf, wi[:, 2] / np.pi, rtol=1e-5)
    # The glTF BRDF is reciprocal: f(wo, wi) = f(wi, wo), the cosine aside.
    gold = canopy.pbr((1.0, 0.77, 0.34), metallic=0.7, roughness=0.5)
    there, _ = canopy.eval_material(gold, wo, wi)
    back, _ = canopy.eval_material(gold, wi, wo)
    np.testing.assert_allclose(there / wi[:, 2:], back / wo[:, 2:], rtol=1e-4)
    # Nothing is reflected below the surface.
    below = wi * [1, 1, -1]
    value, pdf = canopy.eval_material(gold, wo, below)
    assert not value.any() and not pdf.any()
    with pytest.raises(ValueError, match="wo has 500 rows and wi 2"):
        canopy.eval_material(gold, wo, wi[:2])


def test_point_spot_and_directional_lights_light_the_scene_as_the_scene_file_does(tmp_path):
    path = tmp_path / "lit.toml"
    path.write_text("""
background = [0, 0, 0]
camera = { look_from = [0, 4, 6], look_at = [0, 0, 0] }
render = { width = 24, height = 16, spp = 4 }
[[cuboids]]
min = [-5, -1, -5]
max = [5, 0, 5]
material = { type = "pbr", base_color = [0.7, 0.7, 0.7], roughness = 0.6 }
[[lights]]
type = "point"
position = [0, 2, 0]
intensity = [5, 5, 5]
[[lights]]
type = "spot"
position = [2, 3, 0]
direction = [-1, -2, 0]
intensity = [10, 8, 6]
inner_angle = 10
outer_angle = 30
[[lights]]
type = "directional"
direction = [1, -2, 0]
irradiance = [0.5, 0.5, 0.5]
""")
    from_file = canopy.render(str(path))
    scene = canopy.Scene(size=(24, 16), spp=4)
    scene.camera(look_from=(0, 4, 6), look_at=(0, 0, 0))
    scene.background((0, 0, 0))
    scene.add_box((-5, -1, -5), (5, 0, 5), material=canopy.pbr((0.7, 0.7, 0.7), roughness=0.6))
    scene.add_point_light((0, 2, 0), (5, 5, 5))
    scene.add_spot_light((2, 3, 0), (-1, -2, 0), (10, 8, 6), inner_angle=10, outer_angle=30)
    scene.add_directional_light((1, -2, 0), (0.5, 0.5, 0.5))
    image = canopy.render(scene)
    assert image.mean() > 0.01
    np.testing.assert_array_equal(image, from_file)
    with pytest.raises(ValueError, match="outer cone must be wider"):
        scene.add_spot_light((0, 1, 0), (0, -1, 0), (1, 1, 1), inner_angle=40, outer_angle=30)
    with pytest.raises(ValueError, match="add_directional_light: `direction`"):
        scene.add_directional_light((0, 0, 0), (1, 1, 1))


def test_an_orthographic_camera_shows_true_sizes():
    # A glowing disc-on-sight (sphere of radius 1) seen by parallel rays from a view 4
    # high covers pi / 16 of a square image, wherever the camera stands back.
    scene = canopy.Scene()
    scene.settings(size=(64, 64), spp=4, max_depth=1, integrator="bsdf")
    scene.background((0.0, 0.0, 0.0))
    scene.add_sphere((0.0, 0.0, 0.0), 1.0, material={"type": "emissive", "radiance": [1, 1, 1]})
    covered = []
    for distance in (5.0, 50.0):
        scene.camera((0.0, 0.0, distance), (0.0, 0.0, 0.0), ortho_height=4.0)
        image = canopy.render(scene)
        covered.append(float(image[..., 0].mean()))
    assert covered[0] == pytest.approx(np.pi / 16, abs=0.01)
    assert covered[1] == pytest.approx(covered[0], abs=1e-3)
    assert scene.info().contents()["camera"]["ortho_height"] == 4.0
    # A frame may switch the camera to perspective and back.
    perspective = canopy.render(scene, camera={"ortho_height": None, "vfov": 20.0})
    assert perspective[..., 0].mean() < 0.9 * covered[1]
    with pytest.raises(ValueError, match="ortho_height"):
        scene.camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), ortho_height=-1.0)


def test_a_glowing_metallic_roughness_material_lights_the_scene():
    # The only light: a reflecting sphere that also glows.
    scene = canopy.Scene()
    scene.settings(size=(24, 24), spp=4, max_depth=3)
    scene.background((0.0, 0.0, 0.0))
    scene.camera((0.0, 1.0, 6.0), (0.0, 0.5, 0.0))
    scene.add_box((-3, -0.1, -3), (3, 0, 3), material=canopy.lambertian((0.6, 0.6, 0.6)))
    glow = canopy.pbr((0.5, 0.5, 0.5), roughness=0.4, emission=(3.0, 2.0, 1.0))
    scene.add_sphere((0.0, 1.0, 0.0), 0.5, material=glow)
    image = canopy.render(scene)
    assert image.mean() > 0.01
    # Warm light: more red than blue on the floor too.
    assert image[..., 0].mean() > image[..., 2].mean()
    materials = scene.info().contents()["materials"]
    assert [m.get("emission") for m in materials if m["type"] == "pbr"] == [[3.0, 2.0, 1.0]]
    with pytest.raises(ValueError, match="emission"):
        scene.add_material(canopy.pbr((0.5, 0.5, 0.5), emission=(-1.0, 0.0, 0.0)))


def _triangle_gltf(buffer_uri: str) -> str:
    return json.dumps({
        "asset": {"version": "2.0"}, "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "buffers": [{"byteLength": 36, "uri": buffer_uri}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]}],
    })


def test_a_scene_reads_only_its_own_folder_unless_allowed(tmp_path):
    """Files a scene names outside its folder (``../``, absolute, percent-encoded) are
    refused by load_scene, render and Scene.add_gltf, and read where allow_paths allows;
    a pickled scene keeps its allowance."""
    outside, models = tmp_path / "outside", tmp_path / "models"
    outside.mkdir()
    models.mkdir()
    (outside / "tri.bin").write_bytes(np.array([0, 0, 0, 1, 0, 0, 0, 1, 0], np.float32).tobytes())
    (outside / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (models / "scene.toml").write_text(
        '[camera]\nlook_from = [0, 0, 3]\nlook_at = [0, 0, 0]\n[render]\nwidth = 8\nheight = 8\nspp = 1\n'
        '[[meshes]]\nfile = "../outside/tri.obj"\nmaterial = { type = "lambertian", albedo = [0.5, 0.5, 0.5] }\n')
    for call in (lambda **k: canopy.load_scene(models / "scene.toml", **k),
                 lambda **k: canopy.render(models / "scene.toml", **k)):
        with pytest.raises(ValueError, match="leads out of the scene's folder"):
            call()
        call(allow_paths=[outside])
    for uri in ("../outside/tri.bin", "%2e%2e/outside/tri.bin", str(outside / "tri.bin")):
        (models / "m.gltf").write_text(_triangle_gltf(uri))
        scene = canopy.Scene()
        with pytest.raises(ValueError, match="leads out of the scene's folder"):
            scene.add_gltf(models / "m.gltf")
        assert scene.add_gltf(models / "m.gltf", allow_paths=[outside]) == 1
        again = pickle.loads(pickle.dumps(scene))
        assert again.info().counts == scene.info().counts
