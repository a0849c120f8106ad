"""The renderer from Python: the CLI's pixels exactly, progress, errors."""

import os
import subprocess

import numpy as np
import pytest

import canopy_rt as canopy


def test_render_matches_the_cli_exr_bit_for_bit(canopy_bin, tmp_path):
    exr = tmp_path / "cornell.exr"
    subprocess.run(
        [canopy_bin, "render", "cornell", "--size", "24x16", "--spp", "3", "--seed", "5", "-o", exr],
        check=True,
        capture_output=True,
    )
    from_cli = canopy.read_image(exr)
    image = canopy.render("cornell", size=(24, 16), spp=3, seed=5)
    assert image.shape == (16, 24, 3) and image.dtype == np.float32
    np.testing.assert_array_equal(image, from_cli)
    assert image.max() > 0


def test_render_options_and_progress():
    calls = []
    image = canopy.render(
        "paper-1",
        size=(12, 10),
        spp=4,
        max_depth=3,
        integrator="bsdf",
        threads=1,
        progress=lambda done, total: calls.append((done, total)),
    )
    assert image.shape == (10, 12, 3)
    assert calls == [(1, 4), (2, 4), (3, 4), (4, 4)]
    # Same seed and settings on more threads: the same pixels.
    again = canopy.render("paper-1", size=(12, 10), spp=4, max_depth=3, integrator="bsdf", threads=2)
    np.testing.assert_array_equal(image, again)


def test_a_failing_progress_callback_stops_the_render():
    def fail(done, total):
        raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        canopy.render("cornell", size=(8, 8), spp=5, progress=fail)


@pytest.mark.parametrize(
    "kwargs, error, words",
    [
        ({"scene": "no-such-scene"}, ValueError, "no-such-scene"),
        ({"scene": "cornell", "device": "gpu", "bvh": "none"}, ValueError, "choose a builder"),
        ({"scene": "cornell", "region": (0, 0, 999, 1)}, ValueError, "beyond"),
        ({"scene": "cornell", "region": (0, 0, 1)}, ValueError, "region must be"),
        ({"scene": "cornell", "threads": 0}, ValueError, "threads must be"),
        ({"scene": "cornell", "checkpoint_every": -1}, ValueError, "checkpoint_every"),
        ({}, ValueError, "needs a scene"),
        ({"resume": "x.checkpoint", "spp": 3}, ValueError, "keeps its checkpoint's settings"),
        ({"resume": "x.checkpoint", "fast_triangles": True}, ValueError, "drop fast_triangles"),
        ({"scene": "cornell", "device": "tpu"}, ValueError, "device must be"),
        ({"scene": "cornell", "integrator": "photons"}, ValueError, "unknown integrator"),
        ({"scene": "cornell", "spp": 0}, ValueError, "spp 0"),
        ({"scene": "cornell", "size": (0, 5)}, ValueError, "empty"),
        ({"scene": "cornell", "bvh": "octree"}, ValueError, "unknown"),
        ({"scene": "cornell", "schedule": "sideways"}, ValueError, "unknown schedule `sideways`"),
        ({"scene": "cornell", "sampler": "halton"}, ValueError, "unknown sampler `halton`"),
        # Integers the native code cannot hold name their argument (not an anonymous
        # OverflowError).
        ({"scene": "cornell", "size": (-1, 10)}, ValueError, "size=(-1, 10) must not be negative"),
        ({"scene": "cornell", "threads": -1}, ValueError, "threads=-1 must not be negative"),
        ({"scene": "cornell", "spp": 1 << 40}, ValueError, "spp=1099511627776 is too large"),
        ({"scene": "cornell", "seed": 1 << 70}, ValueError, "seed=1180591620717411303424 is too large"),
        ({"scene": "cornell", "region": (0, -2, 4, 4)}, ValueError, "region=(0, -2, 4, 4) must not be"),
    ],
)
def test_bad_render_arguments_raise(kwargs, error, words):
    with pytest.raises(error) as e:
        canopy.render(**kwargs)
    assert words in str(e.value), str(e.value)


def test_both_schedules_render_the_same_pixels():
    for sampler in ("sobol", "independent"):
        wavefront = canopy.render("paper-5", size=(24, 18), spp=3, sampler=sampler)
        depth = canopy.render("paper-5", size=(24, 18), spp=3, schedule="depth", sampler=sampler)
        assert wavefront.max() > 0
        np.testing.assert_array_equal(wavefront, depth)


def test_the_sampler_is_a_setting():
    assert canopy.load_scene("cornell").settings["sampler"] == "sobol"
    sobol = canopy.render("cornell", size=(16, 16), spp=4)
    independent = canopy.render("cornell", size=(16, 16), spp=4, sampler="independent")
    assert not np.array_equal(sobol, independent)
    scene = canopy.Scene(size=(8, 8), spp=2, sampler="independent")
    scene.camera(look_from=(0, 0, 4), look_at=(0, 0, 0))
    scene.add_sphere((0, 0, 0), 1.0, material=canopy.lambertian((0.5, 0.5, 0.5)))
    np.testing.assert_array_equal(canopy.render(scene), canopy.render(scene, sampler="independent"))


def test_sample_ranges_make_the_whole_render():
    whole = canopy.render("paper-3", size=(20, 12), spp=5, seed=4)
    np.testing.assert_array_equal(canopy.render("paper-3", size=(20, 12), samples=(0, 5), seed=4), whole)
    first = canopy.render("paper-3", size=(20, 12), samples=(0, 2), seed=4).astype(np.float64)
    rest = canopy.render("paper-3", size=(20, 12), samples=(2, 3), seed=4, region=(4, 2, 10, 6))
    merged = (2 * first[2:8, 4:14] + 3 * rest.astype(np.float64)) / 5
    # The same samples: only the rounding of the sums differs.
    np.testing.assert_allclose(merged, whole[2:8, 4:14], rtol=1e-5, atol=1e-6)
    assert not np.array_equal(first[2:8, 4:14], whole[2:8, 4:14])
    for kwargs, words in [({"samples": (0, 0)}, "count >= 1"), ({"samples": (0, 2), "spp": 2}, "not both"),
                          ({"samples": (0, 2), "checkpoint": "x.ckpt"}, "drop resume")]:
        with pytest.raises(ValueError, match=words):
            canopy.render("paper-3", size=(8, 8), **kwargs)


def test_a_region_is_exactly_those_pixels_of_the_whole_image():
    whole = canopy.render("cornell", size=(20, 12), spp=2)
    part = canopy.render("cornell", size=(20, 12), spp=2, region=(3, 4, 9, 5))
    assert part.shape == (5, 9, 3)
    np.testing.assert_array_equal(part, whole[4:9, 3:12])


def test_a_stopped_render_is_saved_and_resumes_to_the_same_image(tmp_path):
    checkpoint = tmp_path / "cornell.checkpoint"
    uninterrupted = canopy.render("cornell", size=(12, 10), spp=5, seed=3)

    def stop_after_two(done, total):
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        canopy.render("cornell", size=(12, 10), spp=5, seed=3, checkpoint=checkpoint, progress=stop_after_two)
    assert checkpoint.exists()
    calls = []
    resumed = canopy.render(resume=checkpoint, progress=lambda done, total: calls.append(done))
    assert calls == [3, 4, 5]
    np.testing.assert_array_equal(resumed, uninterrupted)
    assert not checkpoint.exists(), "a finished render removes its checkpoint"


def test_a_fast_mode_render_resumes_in_the_fast_mode(tmp_path):
    checkpoint = tmp_path / "fast.checkpoint"
    uninterrupted = canopy.render("paper-3", size=(12, 10), spp=4, fast_triangles=True)

    def stop_after_two(done, total):
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        canopy.render("paper-3", size=(12, 10), spp=4, fast_triangles=True, checkpoint=checkpoint,
                      progress=stop_after_two)
    # The GPU's test is watertight: it would mix two modes' samples.
    with pytest.raises(ValueError, match="fast one"):
        canopy.render(resume=checkpoint, device="gpu")
    assert checkpoint.exists()
    np.testing.assert_array_equal(canopy.render(resume=checkpoint), uninterrupted)


def test_the_gpu_renders_the_cpus_image_within_noise():
    if not canopy.devices():
        pytest.skip("no GPU adapter (not even a software one)")
    cpu = canopy.render("paper-3", size=(32, 24), spp=16, seed=1)
    gpu = canopy.render("paper-3", size=(32, 24), spp=16, seed=1, device="gpu")
    assert gpu.shape == cpu.shape and gpu.dtype == np.float32
    assert not np.array_equal(gpu, np.zeros_like(gpu))
    # The same random streams and estimator: the means agree closely (canopy-gpu's own
    # tests compare tile by tile).
    assert abs(gpu.mean() - cpu.mean()) < 0.03 * cpu.mean()
    part = canopy.render("paper-3", size=(32, 24), spp=16, seed=1, device="gpu", region=(8, 4, 10, 6))
    np.testing.assert_array_equal(part, gpu[4:10, 8:18])


def test_a_broken_scene_file_names_its_line(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text('[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[spheres]]\ncenter = [0, 0, 0]\nradus = 1\n')
    with pytest.raises(ValueError) as e:
        canopy.render(str(scene), size=(4, 4), spp=1)
    assert "bad.toml:6" in str(e.value) and "radus" in str(e.value)


def test_load_scene_describes_it():
    info = canopy.load_scene("cornell")
    assert info.name == "cornell"
    assert info.counts["cuboids"] == 11 and info.counts["emissive_materials"] == 1
    assert info.settings["integrator"] == "path" and info.settings["width"] == 400
    lo, hi = info.bounds
    assert lo[0] <= 0 and hi[0] >= 555
    assert info.warnings == []


def test_load_mesh_reads_obj_and_ply_alike():
    from conftest import MESHES

    v_obj, f_obj = canopy.load_mesh(MESHES / "teapot.obj")
    v_ply, f_ply = canopy.load_mesh(MESHES / "teapot.ply")
    assert f_obj.shape == f_ply.shape == (992, 3)
    assert v_obj.dtype == np.float32 and f_obj.dtype == np.int64
    with pytest.raises(ValueError, match="expected .obj or .ply"):
        canopy.load_mesh("mesh.stl")
    with pytest.raises(OSError):
        canopy.load_mesh(MESHES / "missing.ply")


def test_a_checkpoint_never_goes_over_the_scene_or_a_users_file(tmp_path):
    scene = tmp_path / "s.toml"
    text = '[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[spheres]]\ncenter = [0, 0, 0]\nradius = 1\nmaterial = { type = "lambertian", albedo = [0.5, 0.5, 0.5] }\n'
    scene.write_text(text)
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes")
    for target, words in [(scene, "over an input of the scene"), (notes, "not a canopy checkpoint")]:
        with pytest.raises(ValueError, match=words):
            canopy.render(str(scene), size=(4, 4), spp=1, checkpoint=target)
    assert scene.read_text() == text and notes.read_text() == "my notes"


def test_read_image_refuses_special_files_and_oversized_images(tmp_path):
    """read_image opens only regular files (a FIFO would block it forever, beyond the
    reach of Ctrl-C) and checks the size an image declares before decoding it."""
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    with pytest.raises(OSError, match="not a regular file"):
        canopy.read_image(fifo)
    with pytest.raises(OSError, match="not a regular file"):
        canopy.read_image(tmp_path)
    # A PNG header declaring 20000 x 20000 pixels (400M, past the largest film).
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", 20000, 20000, 8, 2, 0, 0, 0)
    huge = tmp_path / "huge.png"
    huge.write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b"")
    )
    with pytest.raises(OSError, match="huge.png: a 20000x20000 image is larger than"):
        canopy.read_image(huge)


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: canopy.Scene(size=(-1, 10)), "size=(-1, 10) must not be negative"),
        (lambda: canopy.Scene(spp=-3), "spp=-3 must not be negative"),
        (lambda: canopy.RayScene().add_instance(-1), "geometry=-1 must not be negative"),
        (lambda: canopy.RayScene(width=-4), "width=-4 must not be negative"),
        (
            lambda: canopy.Bvh(*canopy.example_mesh(), max_leaf_size=-1),
            "max_leaf_size=-1 must not be negative",
        ),
        (
            lambda: canopy.Bvh(*canopy.example_mesh()).intersect([[0, 0, 0]], [[0, 0, 1]], threads=-2),
            "threads=-2 must not be negative",
        ),
    ],
)
def test_negative_and_huge_integers_name_their_argument(call, words):
    with pytest.raises(ValueError) as e:
        call()
    assert words in str(e.value), str(e.value)


def test_probing_gpus_prints_nothing_on_a_machine_without_a_display():
    # Mesa's device-selection layer printed "XDG_RUNTIME_DIR is invalid" twice per probe.
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("XDG_RUNTIME_DIR", "DISPLAY", "WAYLAND_DISPLAY")}
    probe = "import canopy_rt; canopy_rt.devices(); canopy_rt.devices()"
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr == "", done.stderr
