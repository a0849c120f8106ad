"""canopy_rt.distributed on a real local Ray cluster of two nodes (one CPU each): tiles
rendered by Ray tasks give canopy's single-process image bit for bit, scene files ship
with the files they read, a worker killed mid-task is replaced without changing the
image, a killed driver resumes, and bad set-ups are refused before any work."""

import os

import numpy as np
import pytest

import canopy_rt as canopy
import canopy_rt.distributed as distributed
from conftest import GLTF, MESHES

ray = pytest.importorskip("ray")


@pytest.fixture(scope="module", autouse=True)
def local_ray():
    """A Ray cluster of two nodes on this machine, one CPU each (a head and a second
    node, as `ray start --head` and `ray start --address` make them), shut down at the
    end whatever happens."""
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args=dict(num_cpus=1, include_dashboard=False))
    try:
        cluster.add_node(num_cpus=1)
        ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False)
        cluster.wait_for_nodes()
        yield cluster
    finally:
        ray.shutdown()
        cluster.shutdown()


def test_the_cluster_has_two_nodes_and_tiles_run_on_both():
    alive = [n for n in ray.nodes() if n["Alive"]]
    assert len(alive) == 2 and all(n["Resources"]["CPU"] == 1 for n in alive)

    # Two one-CPU tasks held running side by side must be on different nodes.
    @ray.remote(num_cpus=1)
    def node_while_both_run(barrier):
        ray.get(barrier.arrive.remote())
        while ray.get(barrier.count.remote()) < 2:
            pass
        return ray.get_runtime_context().get_node_id()

    @ray.remote(num_cpus=0)
    class Barrier:
        def __init__(self):
            self.n = 0

        def arrive(self):
            self.n += 1

        def count(self):
            return self.n

    barrier = Barrier.remote()
    nodes = ray.get([node_while_both_run.remote(barrier) for _ in range(2)])
    assert len(set(nodes)) == 2


@pytest.fixture
def address():
    """The test cluster's address, for drivers in other processes (a driver killed by a
    test then leaves no Ray processes of its own behind)."""
    return ray.get_runtime_context().gcs_address


def test_tiles_cover_the_image_once():
    regions = distributed.tiles(50, 33, 16)
    covered = np.zeros((33, 50), int)
    for x, y, w, h in regions:
        covered[y:y + h, x:x + w] += 1
    assert (covered == 1).all() and len(regions) == 4 * 3


def test_a_scene_file_and_its_mesh_render_as_in_one_process(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "teapot.ply").write_bytes((MESHES / "teapot.ply").read_bytes())
    scene = tmp_path / "scenes" / "teapot.toml"
    scene.parent.mkdir()
    scene.write_text("""
background = "sky"
camera = { look_from = [0, 3, 8], look_at = [0, 0.5, 0] }
render = { width = 45, height = 30, spp = 2, seed = 3 }
[[meshes]]
file = "../meshes/teapot.ply"
material = { type = "lambertian", albedo = [0.8, 0.3, 0.2] }
""")
    calls = []
    # The mesh lies beside the scene's folder: read only where allowed, on every worker.
    with pytest.raises(ValueError, match="leads out of the scene's folder"):
        distributed.render(scene, tile=16)
    allowed = [tmp_path / "meshes"]
    image = distributed.render(scene, tile=16, allow_paths=allowed,
                               progress=lambda done, total: calls.append((done, total)))
    np.testing.assert_array_equal(image, canopy.render(str(scene), allow_paths=allowed))
    assert calls == [(i, 6) for i in range(1, 7)]


def test_a_built_in_scene_with_overrides_renders_as_in_one_process():
    image = distributed.render("paper-3", size=(40, 28), spp=2, seed=9, tile=13)
    np.testing.assert_array_equal(image, canopy.render("paper-3", size=(40, 28), spp=2, seed=9))


def test_sample_ranges_as_tasks_merge_to_the_image_up_to_rounding():
    whole = canopy.render("paper-3", size=(30, 20), spp=7, seed=2)
    split = distributed.render("paper-3", size=(30, 20), spp=7, seed=2, tile=16, samples_per_task=3)
    np.testing.assert_allclose(split, whole, rtol=1e-5, atol=1e-6)
    # One range per tile is the single-process call: bit for bit.
    single = distributed.render("paper-3", size=(30, 20), spp=7, seed=2, tile=16, samples_per_task=7)
    np.testing.assert_array_equal(single, whole)
    with pytest.raises(ValueError, match="samples_per_task"):
        distributed.render("paper-3", samples_per_task=0)


def test_bad_set_ups_are_refused_before_work(tmp_path):
    with pytest.raises(ValueError, match="gone.toml"):
        distributed.render(tmp_path / "gone.toml")
    with pytest.raises(ValueError, match="tile"):
        distributed.render("paper-3", tile=0)
    with pytest.raises(ValueError, match="no node of the cluster has a GPU"):
        distributed.render("paper-3", size=(8, 8), spp=1, device="gpu")
    with pytest.raises(ValueError, match="device must be"):
        distributed.render("paper-3", device="tpu")
    with pytest.raises(RuntimeError, match="same version on every node"):
        distributed.render_tile(("paper-3", {}), (0, 0, 1, 1), {}, "0.0.0-elsewhere")


def test_every_node_is_checked_for_canopy_before_work(tmp_path, monkeypatch):
    addresses = distributed.check_nodes()
    assert len(addresses) == 2
    # A driver of another version: refused before any tile is rendered.
    monkeypatch.setattr(distributed, "__version__", "0.0.0-elsewhere")
    kept = tmp_path / "tiles"
    with pytest.raises(RuntimeError) as e:
        distributed.render("paper-3", size=(16, 8), spp=1, tile=8, resume_dir=kept)
    assert str(e.value).count("0.0.0-elsewhere on the driver") == 2, str(e.value)
    assert "same version on every node" in str(e.value)
    assert not list(kept.glob("tile-*"))
    # A node that cannot import canopy_rt is named, with what to install.
    missing = ModuleNotFoundError("No module named 'canopy_rt'")
    assert distributed._node_failure("10.0.0.7", missing, "1.2.3") == (
        "node 10.0.0.7 has no canopy_rt: install canopy-rt 1.2.3 on every node")


def test_workers_render_from_the_shipped_files_alone(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "teapot.ply").write_bytes((MESHES / "teapot.ply").read_bytes())
    scene = tmp_path / "teapot.toml"
    scene.write_text("""
camera = { look_from = [0, 3, 8], look_at = [0, 0.5, 0] }
render = { width = 24, height = 16, spp = 2 }
[[meshes]]
file = "meshes/teapot.ply"
material = { type = "lambertian", albedo = [0.8, 0.3, 0.2] }
""")
    expected = canopy.render(str(scene))
    bundle = distributed._bundle(str(scene))
    assert sorted(bundle[1]) == sorted(str(p) for p in [scene, tmp_path / "meshes" / "teapot.ply"])
    (tmp_path / "meshes" / "teapot.ply").unlink()
    scene.unlink()
    task = ray.remote(distributed.render_tile)
    tile = ray.get(task.remote(bundle, (0, 0, 24, 16), {}, canopy.__version__))
    np.testing.assert_array_equal(tile, expected)


def test_a_python_scene_ships_with_its_files_and_renders_as_in_one_process(tmp_path):
    model = tmp_path / "duck.glb"
    model.write_bytes((GLTF / "Duck.glb").read_bytes())
    scene = canopy.Scene(size=(26, 18), spp=2, name="pond")
    scene.camera(look_from=(0, 2, 6), look_at=(0, 0.5, 0))
    scene.add_sphere((0, -100, 0), 100, material=canopy.lambertian((0.4, 0.5, 0.3)))
    scene.add_gltf(model, np.diag([0.01, 0.01, 0.01, 1.0]))
    expected = canopy.render(scene)
    np.testing.assert_array_equal(distributed.render(scene, tile=9), expected)
    # The workers read the model from what was shipped, not from this disk.
    bundle = distributed._bundle(scene)
    assert sorted(bundle[1]) == [str(model)]
    model.unlink()
    task = ray.remote(distributed.render_tile)
    tile = ray.get(task.remote(bundle, (0, 0, 26, 18), {}, canopy.__version__))
    np.testing.assert_array_equal(tile, expected)


def test_frames_render_as_in_one_process_and_a_rerun_renders_only_the_missing(tmp_path):
    scene = canopy.Scene(size=(20, 14), spp=2)
    scene.camera(look_from=(0, 2, 7), look_at=(0, 0.5, 0))
    scene.add_sphere((0, -100, 0), 100, material=canopy.lambertian((0.5, 0.5, 0.5)))
    vertices, faces = canopy.load_mesh(MESHES / "teapot.obj")
    scene.add_mesh(vertices, faces, material=canopy.lambertian((0.8, 0.3, 0.2)))
    frames = []
    for i in range(3):
        turn = np.eye(4)
        angle = 0.4 * i
        turn[[0, 0, 2, 2], [0, 2, 0, 2]] = np.cos(angle), np.sin(angle), -np.sin(angle), np.cos(angle)
        frames.append({"camera": {"look_from": (i, 2, 7)}, "instances": {0: turn}})
    output = str(tmp_path / "frames" / "f{frame:03d}.exr")
    paths = distributed.render_frames(scene, frames, output)
    assert paths == [str(tmp_path / "frames" / f"f{i:03d}.exr") for i in range(3)]
    for path, frame in zip(paths, frames):
        np.testing.assert_array_equal(canopy.read_image(path), canopy.render(scene, **frame))
    # A rerun renders only what is missing.
    kept = os.stat(paths[0]).st_mtime_ns
    os.remove(paths[1])
    seen = []
    distributed.render_frames(scene, frames, output, progress=lambda done, total: seen.append(done))
    assert seen == [2, 3] and os.stat(paths[0]).st_mtime_ns == kept
    np.testing.assert_array_equal(canopy.read_image(paths[1]), canopy.render(scene, **frames[1]))
    for frames_, output_, words in [([{"lens": 1}], output, "frame 0"),
                                    ([{"camera": {"fov": 3}}], output, "camera takes"),
                                    ([{}, {}], str(tmp_path / "same.exr"), "same file"),
                                    ([{"instances": {0: np.zeros((2, 2))}}], output, "instances"),
                                    ([{"instances": {1: np.eye(4)}}], output, "instance 1 does not exist")]:
        with pytest.raises(ValueError, match=words):
            distributed.render_frames(scene, frames_, output_)


def test_the_command_line_writes_the_image(tmp_path, address):
    import subprocess
    import sys

    out = tmp_path / "paper-3.exr"
    run = subprocess.run(
        [sys.executable, "-m", "canopy_rt.distributed", "render", "paper-3", "-o", str(out),
         "--size", "40x28", "--spp", "2", "--seed", "9", "--tile", "16", "--address", address],
        capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "tiles 6/6" in run.stderr
    np.testing.assert_array_equal(canopy.read_image(out), canopy.render("paper-3", size=(40, 28), spp=2, seed=9))
    bad = subprocess.run([sys.executable, "-m", "canopy_rt.distributed", "render", "gone.toml",
                          "-o", str(tmp_path / "x.png")], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 1 and "gone.toml" in bad.stderr
    assert not (tmp_path / "x.png").exists()


def test_the_command_line_renders_frames_from_a_json_file(tmp_path, address):
    import json
    import subprocess
    import sys

    frames = [{"camera": {"look_from": [x, 3, 9]}} for x in (-1, 1)]
    (tmp_path / "frames.json").write_text(json.dumps(frames))
    run = subprocess.run(
        [sys.executable, "-m", "canopy_rt.distributed", "frames", "paper-3", "--frames",
         str(tmp_path / "frames.json"), "-o", str(tmp_path / "f{frame}.exr"), "--size", "16x12",
         "--spp", "1", "--address", address], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    for i, frame in enumerate(frames):
        np.testing.assert_array_equal(canopy.read_image(tmp_path / f"f{i}.exr"),
                                      canopy.render("paper-3", size=(16, 12), spp=1, **frame))
    (tmp_path / "bad.json").write_text("{")
    bad = subprocess.run([sys.executable, "-m", "canopy_rt.distributed", "frames", "paper-3",
                          "--frames", str(tmp_path / "bad.json"), "-o", "f{frame}.exr"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 1 and "bad.json: not JSON" in bad.stderr


def test_bench_paper_cells_run_as_tasks_into_one_table(canopy_bin, tmp_path):
    seen = []
    md = distributed.bench_paper(tmp_path / "bench", scenes=[2, 3], methods="report", runs=2,
                                 size=(12, 12), spp=1, fast_triangles=True, canopy_bin=str(canopy_bin),
                                 progress=lambda done, total: seen.append((done, total)))
    assert seen[-1] == (2 * 6 * 2, 24)
    import json

    record = json.loads((tmp_path / "bench" / "results.json").read_text())
    cells = record["measurements"]
    assert [(m["scene"], m["method"]) for m in cells[:2]] == [("paper-2", "No BVH"), ("paper-2", "Top Down x sorted")]
    assert len(cells) == 12 and all(len(m["seconds"]) == 2 for m in cells)
    assert all(m["speedup"] is not None and m["speedup"] > 0 for m in cells)
    text = open(md).read()
    assert "paper-3" in text and "Agglom. 8 children" in text and "as Ray tasks" in text
    assert (tmp_path / "bench" / "table3.png").exists()
    # Every cell rendered with the fast triangle test, and the record says so.
    assert record["config"]["triangles"] == "fast" and "fast triangle test" in record["settings"]
    with pytest.raises(ValueError, match="scenes are numbers"):
        distributed.bench_paper(tmp_path / "x", scenes=[7], canopy_bin=str(canopy_bin))
    with pytest.raises(ValueError, match="cannot run"):
        distributed.bench_paper(tmp_path / "x", canopy_bin=str(tmp_path / "no-canopy"))


def test_write_image_round_trips_exr_and_refuses_bad_images(tmp_path):
    image = np.random.default_rng(1).random((5, 7, 3), dtype=np.float32) * 4
    canopy.write_image(tmp_path / "a.exr", image)
    np.testing.assert_array_equal(canopy.read_image(tmp_path / "a.exr"), image)
    with pytest.raises(ValueError, match="not finite"):
        canopy.write_image(tmp_path / "b.exr", np.full((2, 2, 3), np.nan, np.float32))
    with pytest.raises(ValueError, match="shape"):
        canopy.write_image(tmp_path / "c.exr", np.zeros((2, 2, 4), np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr"]


def test_a_driver_started_again_renders_only_the_missing_tiles(tmp_path):
    store = tmp_path / "tiles"
    settings = dict(size=(40, 28), spp=2, seed=9, tile=16, resume_dir=store)
    expected = canopy.render("paper-3", size=(40, 28), spp=2, seed=9)
    first = distributed.render("paper-3", **settings)
    np.testing.assert_array_equal(first, expected)
    kept = sorted(p.name for p in store.iterdir())
    assert len(kept) == 7 and "render.json" in kept
    # A driver that died after some tiles: two are missing.
    (store / "tile-0-0.exr").unlink()
    (store / "tile-32-16.exr").unlink()
    calls = []
    again = distributed.render("paper-3", progress=lambda d, t: calls.append(d), **settings)
    np.testing.assert_array_equal(again, expected)
    assert calls == [4, 5, 6], "four tiles came from the directory, two were rendered"
    with pytest.raises(ValueError, match="another render"):
        distributed.render("paper-3", **{**settings, "seed": 10})


def test_a_killed_command_line_driver_resumes(tmp_path, address):
    import subprocess
    import sys
    import time

    store = tmp_path / "tiles"
    out = tmp_path / "image.exr"
    command = [sys.executable, "-m", "canopy_rt.distributed", "render", "paper-3", "-o", str(out),
               "--size", "64x48", "--spp", "4", "--seed", "2", "--tile", "8",
               "--resume-dir", str(store), "--address", address]
    driver = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    # Killed once it has kept some tiles (an event, not a time: the directory is watched).
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and driver.poll() is None:
        if len(list(store.glob("tile-*.exr"))) >= 3:
            break
        time.sleep(0.05)
    driver.kill()
    driver.wait()
    kept_before = len(list(store.glob("tile-*.exr")))
    assert kept_before >= 3 and not out.exists() or kept_before == 48
    run = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    np.testing.assert_array_equal(canopy.read_image(out),
                                  canopy.render("paper-3", size=(64, 48), spp=4, seed=2))


def test_a_built_in_scene_is_not_taken_for_a_file_of_its_name(tmp_path, monkeypatch):
    assert "paper-3" in canopy.scenes() and "cornell" in canopy.scenes()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "paper-3").write_text("not a scene file")
    assert distributed._bundle("paper-3") == ("paper-3", {})


def _render_tile_workers():
    """Pids of the Ray workers running a tile now (Ray titles a busy worker
    `ray::<task>`)."""
    import os

    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                title = f.read()
        except OSError:
            continue
        if title.startswith(b"ray::render_tile"):
            found.append(int(pid))
    return found


@pytest.mark.skipif(not __import__("os").path.isdir("/proc"), reason="finds workers through /proc")
def test_a_worker_killed_mid_task_is_replaced_and_the_image_is_the_same():
    import os
    import signal
    import threading
    import time

    settings = dict(size=(32, 16), spp=2048, seed=5)
    result = {}
    driver = threading.Thread(target=lambda: result.update(
        image=distributed.render("paper-3", tile=16, **settings)))
    driver.start()
    # Killed once seen rendering (an event, not a time: the processes are watched).
    killed = None
    deadline = time.monotonic() + 240
    while killed is None and driver.is_alive() and time.monotonic() < deadline:
        for pid in _render_tile_workers():
            os.kill(pid, signal.SIGKILL)
            killed = pid
            break
        time.sleep(0.005)
    driver.join(300)
    assert killed is not None, "no worker was seen rendering"
    assert not driver.is_alive() and "image" in result
    np.testing.assert_array_equal(result["image"], canopy.render("paper-3", **settings))


def test_the_ray_renderer_follows_the_one_output_policy(tmp_path, monkeypatch):
    """Outputs are checked before any tile renders, as `canopy render` checks `-o`:
    not the scene's own files (its environment map, by a link too), not a missing
    folder, not a render's checkpoint; resume folders hold a record or nothing, and
    records are written through unpredictable temporary names (a planted link is
    never followed)."""
    import os

    sky = np.ones((4, 8, 3), np.float32)
    canopy.write_image(tmp_path / "sky.exr", sky)
    scene = tmp_path / "lit.toml"
    scene.write_text('background = { environment = "sky.exr" }\n'
                     '[camera]\nlook_from = [0, 0, 3]\nlook_at = [0, 0, 0]\n'
                     '[render]\nwidth = 8\nheight = 8\nspp = 1\n'
                     '[[spheres]]\ncenter = [0, 0, 0]\nradius = 1\n'
                     'material = { type = "lambertian", albedo = [0.5, 0.5, 0.5] }\n')
    os.symlink(tmp_path / "sky.exr", tmp_path / "sky-link.exr")
    started = []
    monkeypatch.setattr(distributed, "_tasks", lambda *a, **k: started.append(1) or (_ for _ in ()).throw(AssertionError("work started")))
    for output, words in [(tmp_path / "sky.exr", "over an input of the scene"),
                          (tmp_path / "sky-link.exr", "over an input of the scene"),
                          (tmp_path / "gone" / "x.png", "does not exist"),
                          (tmp_path / "x.bmp", "unsupported image format")]:
        with pytest.raises(ValueError, match=words):
            distributed.render(scene, output=output)
        assert distributed.main(["render", str(scene), "-o", str(output)]) == 1
    assert started == [] and (tmp_path / "sky.exr").exists()
    np.testing.assert_array_equal(canopy.read_image(tmp_path / "sky.exr"), sky)
    # Another render's checkpoint, whatever its name, is its unfinished work.
    with pytest.raises(KeyboardInterrupt):
        canopy.render("paper-3", size=(8, 8), spp=4, checkpoint=tmp_path / "ck.png",
                      progress=lambda done, total: (_ for _ in ()).throw(KeyboardInterrupt()))
    with pytest.raises(ValueError, match="holds a canopy checkpoint"):
        distributed.render("paper-3", output=tmp_path / "ck.png")
    # Tiles without a record are refused; a link planted where an old driver put its
    # temporary record is never written through.
    orphans = tmp_path / "orphans"
    orphans.mkdir()
    (orphans / "tile-0-0.exr").write_bytes(b"someone's tile")
    with pytest.raises(ValueError, match="no render.json"):
        distributed.render("paper-3", resume_dir=orphans)
    monkeypatch.undo()
    store = tmp_path / "store"
    store.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("mine")
    os.symlink(victim, store / "render.json.tmp")
    distributed.render("paper-3", size=(8, 8), spp=1, tile=8, resume_dir=store)
    assert victim.read_text() == "mine" and (store / "render.json").is_file()


def test_an_image_that_cannot_be_written_is_kept_elsewhere(tmp_path, monkeypatch):
    """The driver's final write failing (a full disk) does not lose the render: the
    image is kept beside the output, else here, else in the temporary folder."""
    image = np.full((2, 3, 3), 0.25, np.float32)
    real = distributed.write_image
    full = str(tmp_path / "full")

    def write(path, data):
        if str(path).startswith(full):
            raise OSError(f"{path}: cannot write the image: No space left on device")
        real(path, data)

    monkeypatch.setattr(distributed, "write_image", write)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(OSError, match="No space left on device.*kept in") as e:
        distributed._with_output(image, tmp_path / "full" / "out.png")
    kept = tmp_path / "out.png.kept.exr"
    assert str(kept) in str(e.value)
    np.testing.assert_array_equal(canopy.read_image(kept), image)


def test_a_denoised_render_is_the_single_process_one_and_resumes(tmp_path):
    try:
        canopy.denoise(np.zeros((1, 1, 3), np.float32))
    except RuntimeError:
        if __import__("os").environ.get("CANOPY_REQUIRE_OIDN"):
            raise
        pytest.skip("Open Image Denoise is not installed (scripts/oidn.sh)")
    settings = dict(size=(40, 28), spp=4, seed=9)
    expected = canopy.render("cornell", denoise=True, **settings)
    store = tmp_path / "tiles"
    image = distributed.render("cornell", tile=16, denoise=True, resume_dir=store, **settings)
    np.testing.assert_array_equal(image, expected)
    kept = sorted(p.name for p in store.iterdir())
    assert "tile-16-0.albedo.exr" in kept and "tile-16-0.normal.exr" in kept, kept
    # A driver started again takes the tiles and their guides from the folder.
    (store / "tile-0-0.exr").unlink()
    again = distributed.render("cornell", tile=16, denoise=True, resume_dir=store, **settings)
    np.testing.assert_array_equal(again, expected)
    with pytest.raises(ValueError, match="samples_per_task"):
        distributed.render("cornell", denoise=True, samples_per_task=2, **settings)
