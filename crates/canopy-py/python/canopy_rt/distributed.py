"""Rendering on a cluster with `Ray <https://ray.io>`_: the image split into tiles, each
rendered by a Ray task through canopy's own render (``canopy_rt.render(region=...)``),
the tiles put back together on the driver. A tile's pixels are exactly those of the whole
image, so the result is ``canopy render``'s image bit for bit, however the tiles fall on
the machines.

>>> import canopy_rt.distributed                                      # doctest: +SKIP
>>> image = canopy_rt.distributed.render("scene.toml", spp=256, tile=64)   # doctest: +SKIP

From a shell: ``python -m canopy_rt.distributed render scene.toml -o image.exr --address
auto`` (``--help`` lists the options).

The scene (a built-in scene's name, or a scene file, mesh or glTF model and every file it
reads) is loaded and checked on the driver, and its files are shipped once through Ray's
object store; a worker writes them into a private directory, keeping their places relative
to each other, and renders from there. ``ray.init(address=...)`` is called when Ray is not
started yet (``address=None`` starts a local Ray on this machine; ``"auto"`` joins the
cluster this machine belongs to). Before any work, every node is checked to have
canopy_rt of the driver's version (:func:`check_nodes`). A task whose worker dies is
run again by Ray.

With ``resume_dir=``, every finished tile is kept there as an EXR file (written
atomically, its float32 pixels exact) beside a record of the scene and settings; a driver
started again with the same arguments renders only the tiles that are missing, and
refuses a directory that holds another render's tiles.

Tiles may be split into ranges of samples too (``samples_per_task``); see :func:`render`
for how that image differs in rounding.

A scene built in Python (:class:`canopy_rt.Scene`) ships as the calls that build it,
with the files they read (glTF models, environment maps).

Animations: :func:`render_frames` renders one task per frame (camera and instance
moves per frame), each written atomically, skipping frames already on disk.

The laboratory: :func:`bench_paper` runs ``canopy bench paper``'s cells (scene x
method x run) as tasks, each through the node's own ``canopy`` program, one table out.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import tempfile
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _canopy
from . import Scene, __version__, _render_options, load_scene, read_image, scenes, write_image
from .scene import _transform
from . import denoise as denoise_image
from . import render as render_locally

_Region = Tuple[int, int, int, int]


def _ray():
    try:
        import ray
    except ImportError:
        raise ImportError("canopy_rt.distributed needs Ray: pip install ray") from None
    return ray


def tiles(width: int, height: int, tile: int) -> List[_Region]:
    """The regions (x, y, width, height) that cover a width x height image in tiles of
    at most tile x tile pixels, row by row."""
    return [(x, y, min(tile, width - x), min(tile, height - y))
            for y in range(0, height, tile) for x in range(0, width, tile)]


def _described(scene, allow_paths: Sequence = ()):
    """The scene's description (``SceneInfo``); loading it raises, before any work,
    when the scene is bad."""
    return scene.info() if isinstance(scene, Scene) else load_scene(str(scene), allow_paths=allow_paths)


def _bundle(scene, info=None) -> Tuple[object, Dict[str, bytes]]:
    """The scene as tasks receive it: its name or absolute path (or a scene built in
    Python, as the calls that build it), and the bytes of every file it reads by
    absolute path (none for a built-in scene). ``info`` is its description where the
    caller has it already."""
    info = info or _described(scene)
    if isinstance(scene, Scene):
        inputs, source = info.inputs, ("python", scene.__getstate__())
    else:
        scene = str(scene)
        if scene in scenes():  # a built-in scene wins over a file of its name, as in load_scene
            return scene, {}
        inputs, source = [scene, *info.inputs], os.path.abspath(scene)
    files = {}
    for path in inputs:
        path = os.path.abspath(path)
        with open(path, "rb") as f:
            files[path] = f.read()
    return source, files


# Per worker process: the directory a bundle's files were written to, by the bundle's key.
_written: Dict[str, str] = {}


def _written_root(files: Dict[str, bytes]) -> str:
    """The private directory of this worker that holds `files` under their absolute
    paths, written the first time they are asked for."""
    digest = hashlib.sha256()
    for path in sorted(files):
        digest.update(path.encode())
        digest.update(hashlib.sha256(files[path]).digest())
    key = digest.hexdigest()
    root = _written.get(key)
    if root is None:
        root = tempfile.mkdtemp(prefix=f"canopy-{key[:12]}-")
        for path, data in files.items():
            target = _under(root, path)
            os.makedirs(os.path.dirname(target), exist_ok=True)
            with open(target, "wb") as f:
                f.write(data)
        _written[key] = root
    return root


def _under(root: str, path: str) -> str:
    return os.path.join(root, os.path.splitdrive(path)[1].lstrip("/\\"))


def _materialize(source, files: Dict[str, bytes]):
    """What to render on this worker: the scene's files written once into a private
    directory, so that relative references still resolve, and the scene (a name, a path
    there, or a Python scene rebuilt to read its files from there)."""
    if isinstance(source, tuple):
        root = _written_root(files) if files else None
        return Scene._rebuilt(source[1], (lambda path: _under(root, path)) if root else (lambda path: path))
    if not files:
        return source
    return _under(_written_root(files), source)


def _same_version(version: str) -> None:
    """Refuses to work for a driver of another canopy_rt version than this worker's."""
    if version != __version__:
        raise RuntimeError(
            f"canopy_rt {__version__} on this worker, {version} on the driver: install the "
            "same version on every node")


def _tasks(function, address: Optional[str], threads_per_task: int, device: str = "cpu"):
    """Ray, joined or started, and `function` as its task on ``threads_per_task`` CPUs
    (and a GPU for ``device="gpu"``), retried where a worker dies; every node is checked
    first (:func:`check_nodes`)."""
    ray = _ray()
    if not ray.is_initialized():
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    check_nodes(__version__)
    gpus = 1 if device == "gpu" else 0
    if gpus and not ray.cluster_resources().get("GPU"):
        raise ValueError('device="gpu" but no node of the cluster has a GPU (Ray counts none)')
    return ray, ray.remote(num_cpus=int(threads_per_task), num_gpus=gpus, max_retries=3)(function)


def _as_they_finish(ray, pending: dict, take: Callable[[object, object], None]) -> None:
    """Calls ``take(key, result)`` for each task of ``pending`` ({task: key}) as it
    finishes; the tasks still running are cancelled if anything fails."""
    try:
        while pending:
            finished, _ = ray.wait(list(pending), num_returns=1)
            for ref in finished:
                take(pending.pop(ref), ray.get(ref))
    finally:
        for ref in pending:
            ray.cancel(ref)


def render_tile(bundle, region: Optional[_Region], options: dict, version: str):
    """One tile (or with ``region`` None, a whole frame), as a Ray task runs it
    (callable directly too), with its AOVs where ``options`` asks for them: the
    driver's canopy version must be this worker's."""
    _same_version(version)
    source, files = bundle
    scene = _materialize(source, files)
    if files and options.get("allow_paths"):
        # The allowed folders, as the scene's files were written on this worker.
        root = _written_root(files)
        mapped = [_under(root, path) for path in options["allow_paths"]]
        options = dict(options, allow_paths=[path for path in mapped if os.path.isdir(path)])
    return render_locally(scene, region=region, **options)


def _node_version() -> Tuple[str, str]:
    """This node's address and canopy_rt version (a node without canopy_rt cannot even
    load this function: Ray reports that it cannot import it)."""
    import ray

    return ray.util.get_node_ip_address(), __version__


def _node_failure(node: str, error: BaseException, version: str) -> str:
    """What went wrong with a node's check, in words a user acts on."""
    text = str(error)
    if "No module named 'canopy_rt'" in text or "No module named 'canopy_rt." in text:
        return f"node {node} has no canopy_rt: install canopy-rt {version} on every node"
    return f"node {node} could not run canopy_rt {version}: {text.strip().splitlines()[-1]}"


def check_nodes(version: str = __version__, timeout: float = 120.0) -> List[str]:
    """Runs a small task on every alive node of the connected Ray cluster (pinned to it)
    and raises RuntimeError, naming each node at fault, where canopy_rt is missing or
    another version than ``version``; returns the nodes' addresses. ``render`` calls
    this before it starts any work."""
    ray = _ray()
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    nodes = [n for n in ray.nodes() if n.get("Alive")]
    probe = ray.remote(num_cpus=0, max_retries=0)(_node_version)
    pending = {
        probe.options(scheduling_strategy=NodeAffinitySchedulingStrategy(n["NodeID"], soft=False)).remote():
        n.get("NodeManagerAddress", n["NodeID"])
        for n in nodes
    }
    faults, addresses = [], []
    for ref, node in pending.items():
        try:
            address, found = ray.get(ref, timeout=timeout)
        except ray.exceptions.GetTimeoutError:
            faults.append(f"node {node} did not answer within {timeout:.0f} s")
            continue
        except Exception as e:  # a node's own failure, reported with the others
            faults.append(_node_failure(node, e, version))
            continue
        addresses.append(address)
        if found != version:
            faults.append(f"canopy_rt {found} on node {address}, {version} on the driver: "
                          "install the same version on every node")
    if faults:
        raise RuntimeError("; ".join(faults))
    return addresses


class _TileStore:
    """Finished tiles of one render kept in a directory: `render.json` says which
    render (scene file contents, settings, tiling), each tile is `tile-X-Y.exr`."""

    def __init__(self, directory, record: dict, inputs: Sequence[str] = ()):
        self.directory = str(directory)
        os.makedirs(self.directory, exist_ok=True)
        path = os.path.join(self.directory, "render.json")
        if os.path.exists(path):
            try:
                with open(path) as f:
                    found = json.load(f)
            except (OSError, ValueError) as e:
                raise ValueError(f"{path}: not the record of a canopy render ({e}): give an empty directory") from None
            if found != record:
                raise ValueError(f"{self.directory} holds the tiles of another render "
                                 "(other scene, settings or tiling): give an empty directory")
        else:
            # Tiles without a record are of a render nobody can name: never mixed in.
            if any(name.startswith("tile-") for name in os.listdir(self.directory)):
                raise ValueError(f"{self.directory} holds tiles but no render.json saying which render "
                                 "they belong to: give an empty directory")
            _canopy.check_output(path, "resume record", "data", list(inputs))
            _canopy.write_file(path, json.dumps(record).encode())
        _canopy.check_output(self.path((0, 0, 1, 1)), "tile", "image", list(inputs))

    def path(self, region: _Region, layer: Optional[str] = None) -> str:
        name = f"tile-{region[0]}-{region[1]}" + (f".{layer}" if layer else "")
        return os.path.join(self.directory, name + ".exr")

    def load(self, region: _Region, layers: Sequence[str] = ()) -> Optional[Tuple[np.ndarray, dict]]:
        """The tile and its AOV `layers` (each `tile-X-Y.LAYER.exr`), if all are kept."""
        paths = [self.path(region)] + [self.path(region, layer) for layer in layers]
        if not all(os.path.exists(path) for path in paths):
            return None
        images = [read_image(path) for path in paths]
        if any(image.shape != (region[3], region[2], 3) for image in images):
            return None
        return images[0], dict(zip(layers, images[1:]))

    def keep(self, region: _Region, tile: np.ndarray, aovs: Optional[dict] = None) -> None:
        # The layers first: a tile file says the whole tile is kept. Each write is
        # atomic: a killed driver leaves no half tile.
        for layer, image in (aovs or {}).items():
            write_image(self.path(region, layer), image)
        write_image(self.path(region), tile)


def render(
    scene,
    *,
    spp: Optional[int] = None,
    size: Optional[Tuple[int, int]] = None,
    seed: Optional[int] = None,
    max_depth: Optional[int] = None,
    integrator: Optional[str] = None,
    russian_roulette: Optional[bool] = None,
    sampler: Optional[str] = None,
    bvh: str = "binned-sah",
    width: int = 8,
    max_leaf_size: Optional[int] = None,
    fast_triangles: bool = False,
    schedule: str = "wavefront",
    device: str = "cpu",
    tile: int = 64,
    samples_per_task: Optional[int] = None,
    threads_per_task: int = 1,
    address: Optional[str] = None,
    progress: Optional[Callable[[int, int], None]] = None,
    resume_dir=None,
    allow_paths: Sequence = (),
    output=None,
    denoise: bool = False,
) -> np.ndarray:
    """Renders ``scene`` on a Ray cluster: the same linear float32 (height, width, 3)
    image as :func:`canopy_rt.render` with the same settings, bit for bit. The image is
    split into tiles of ``tile`` x ``tile`` pixels, one Ray task each, each task using
    ``threads_per_task`` threads (and asking Ray for as many CPUs); with
    ``device="gpu"`` each task renders on a GPU of its node and asks Ray for one (the
    CPU's image up to rounding, as :func:`canopy_rt.render` says). ``progress(done,
    total)`` is called on the driver as tiles finish (tiles found in ``resume_dir`` count
    as finished at the start).

    With ``samples_per_task``, each tile's samples are split too, into ranges of that
    many, one task each (more tasks than tiles, for few large tiles or many machines).
    A tile's ranges are merged on the driver in sample order, in double precision:
    the image then differs from the single-process one only by the rounding of the
    per-pixel sums (relative differences of about 1e-7 per sample), because those
    add each sample to a float32 sum in turn, which no split can repeat without
    waiting for the previous range.

    A scene file reads only the files in its own folder; ``allow_paths`` names further
    folders, as for :func:`canopy_rt.render` (their files the scene reads are shipped
    to the workers with it).

    With ``output=path`` the image is also written there (``.png`` or ``.exr``,
    atomically), and the path is checked before any tile is rendered, as ``canopy
    render`` checks its ``-o``: its format, its folder, that it is none of the scene's
    files (links count) and holds no render's checkpoint.

    The render options (``spp`` to ``schedule``, :data:`canopy_rt.RENDER_OPTIONS`) are
    :func:`canopy_rt.render`'s, but for ``threads``: each task's are
    ``threads_per_task``.

    ``denoise=True`` has every tile render its albedo and normal too, and denoises the
    whole image on the driver once the tiles are in (a tile denoised alone would show
    seams): the image :func:`canopy_rt.render` gives with ``denoise=True``. Open Image
    Denoise must be found on the driver (checked before any tile); tiles cannot be split
    into sample ranges then."""
    given = _render_options(locals())
    if int(tile) < 1:
        raise ValueError(f"tile must be at least 1 pixel, not {tile}")
    if samples_per_task is not None and int(samples_per_task) < 1:
        raise ValueError(f"samples_per_task must be at least 1, not {samples_per_task}")
    if int(threads_per_task) < 1:
        raise ValueError(f"threads_per_task must be at least 1, not {threads_per_task}")
    allow_paths = [os.path.abspath(p) for p in allow_paths]
    info = _described(scene, allow_paths)
    inputs = _inputs(scene, info)
    if output is not None:
        _canopy.check_output(str(output), "image", "image", inputs)
    bundle = _bundle(scene, info)
    settings = info.settings
    image_width, image_height = (int(size[0]), int(size[1])) if size else (settings["width"], settings["height"])
    if device not in ("cpu", "gpu"):
        raise ValueError(f'device must be "cpu" or "gpu", not {device!r}')
    options = dict(given, size=(image_width, image_height), threads=int(threads_per_task))
    if allow_paths:
        options["allow_paths"] = allow_paths

    total_spp = int(spp) if spp is not None else settings["spp"]
    step = int(samples_per_task) if samples_per_task else total_spp
    ranges = [(first, min(step, total_spp - first)) for first in range(0, total_spp, step)]
    layers = []
    if denoise:
        if len(ranges) > 1:
            raise ValueError("denoise=True renders whole tiles: drop samples_per_task")
        denoise_image(np.zeros((1, 1, 3), np.float32))  # OIDN found, or the error now
        layers = ["albedo", "normal"]
        options["aovs"] = layers
    regions = tiles(image_width, image_height, int(tile))
    image = np.zeros((image_height, image_width, 3), np.float32)
    guides = {layer: np.zeros_like(image) for layer in layers}
    store = None
    if resume_dir is not None:
        digest = hashlib.sha256()
        for path in sorted(bundle[1]):
            digest.update(path.encode() + hashlib.sha256(bundle[1][path]).digest())
        source = bundle[0]
        if isinstance(source, tuple):  # a Python scene: named by the calls that build it
            source = "python:" + hashlib.sha256(pickle.dumps(source[1], protocol=4)).hexdigest()
        record = dict(scene=source, files=digest.hexdigest(), tile=int(tile),
                      samples_per_task=step if len(ranges) > 1 else None,
                      version=__version__, **{k: v for k, v in options.items() if k != "threads"})
        store = _TileStore(resume_dir, json.loads(json.dumps(record)), inputs)
    todo = []
    for region in regions:
        kept = store.load(region, layers) if store else None
        if kept is None:
            todo.append(region)
        else:
            x, y, w, h = region
            image[y:y + h, x:x + w] = kept[0]
            for layer, part in kept[1].items():
                guides[layer][y:y + h, x:x + w] = part
    done = len(regions) - len(todo)
    if progress is not None and done:
        progress(done, len(regions))

    def finished() -> np.ndarray:
        final = denoise_image(image, guides["albedo"], guides["normal"]) if denoise else image
        return _with_output(final, output)

    if not todo:
        return finished()

    ray, task = _tasks(render_tile, address, threads_per_task, device)
    bundle_ref = ray.put(bundle)

    def options_for(first: int, count: int) -> dict:
        if len(ranges) == 1:
            return options  # the whole render's own call: its image bit for bit
        return dict(options, spp=None, samples=(first, count))

    pending = {task.remote(bundle_ref, region, options_for(*part), __version__): (region, k)
               for region in todo for k, part in enumerate(ranges)}
    parts: Dict[_Region, Dict[int, np.ndarray]] = {}

    def take(key, result) -> None:
        nonlocal done
        region, k = key
        mean, aovs = result if layers else (result, {})
        x, y, w, h = region
        for layer in layers:
            guides[layer][y:y + h, x:x + w] = aovs[layer]
        parts.setdefault(region, {})[k] = mean
        if len(parts[region]) < len(ranges):
            return
        means = parts.pop(region)
        if len(ranges) == 1:
            merged = means[0]
        else:
            total = np.zeros(means[0].shape, np.float64)
            for j, (_, count) in enumerate(ranges):
                total += count * means[j].astype(np.float64)
            merged = (total / total_spp).astype(np.float32)
        image[y:y + h, x:x + w] = merged
        if store:
            store.keep(region, merged, aovs)
        done += 1
        if progress is not None:
            progress(done, len(regions))

    _as_they_finish(ray, pending, take)
    return finished()


def _inputs(scene, info) -> List[str]:
    """Every file the scene reads, the scene file itself included: never an output."""
    files = [str(p) for p in info.inputs]
    if not isinstance(scene, Scene) and str(scene) not in scenes():
        files.append(os.path.abspath(str(scene)))
    return files


def _with_output(image: np.ndarray, output) -> np.ndarray:
    """``image``, written to ``output`` first where one is given. When that write fails
    (a full disk, a folder gone), the rendered image is not lost: it is kept as a linear
    EXR beside the output, else in the working directory, else in the temporary
    folder, and the error says where."""
    if output is None:
        return image
    try:
        write_image(output, image)
        return image
    except OSError as error:
        failure = error
    kept_name = os.path.basename(str(output)) + ".kept.exr"
    for folder in (os.path.dirname(os.path.abspath(str(output))), os.getcwd(), tempfile.gettempdir()):
        place = os.path.join(folder, kept_name)
        try:
            write_image(place, image)
        except OSError:
            continue
        raise OSError(f"{failure}; the rendered image is kept in {place} (linear EXR: "
                      f"canopy_rt.read_image reads it)") from failure
    raise failure


_CAMERA_KEYS = {"look_from", "look_at", "up", "vfov", "aperture", "focus_distance", "ortho_height"}


def _frame_changes(index: int, frame, instance_count: int) -> dict:
    """Frame `index`'s changes, checked on the driver: ``camera`` (a dict of camera
    entries) and ``instances`` ({instance index: 4x4 or 3x4 matrix}) of a scene with
    `instance_count` mesh instances."""
    if not isinstance(frame, dict) or not set(frame) <= {"camera", "instances"}:
        raise ValueError(f"frame {index}: a frame is a dict of `camera` and `instances`, not {frame!r}")
    changes = {}
    camera = frame.get("camera")
    if camera is not None:
        if not isinstance(camera, dict) or not set(camera) <= _CAMERA_KEYS:
            raise ValueError(f"frame {index}: camera takes {', '.join(sorted(_CAMERA_KEYS))}, not {camera!r}")
        changes["camera"] = dict(camera)
    instances = frame.get("instances")
    if instances is not None:
        try:
            changes["instances"] = {int(k): _transform(v) for k, v in dict(instances).items()}
        except (TypeError, ValueError) as e:
            raise ValueError(f"frame {index}: instances: {e}") from None
        for k in changes["instances"]:
            if not 0 <= k < instance_count:
                raise ValueError(f"frame {index}: instance {k} does not exist (the scene has "
                                 f"{instance_count})")
    return changes


def render_frames(
    scene,
    frames: Sequence[dict],
    output: str,
    *,
    spp: Optional[int] = None,
    size: Optional[Tuple[int, int]] = None,
    seed: Optional[int] = None,
    max_depth: Optional[int] = None,
    integrator: Optional[str] = None,
    russian_roulette: Optional[bool] = None,
    sampler: Optional[str] = None,
    bvh: str = "binned-sah",
    width: int = 8,
    max_leaf_size: Optional[int] = None,
    fast_triangles: bool = False,
    schedule: str = "wavefront",
    device: str = "cpu",
    threads_per_task: int = 1,
    address: Optional[str] = None,
    progress: Optional[Callable[[int, int], None]] = None,
    allow_paths: Sequence = (),
) -> List[str]:
    """Renders an animation on a Ray cluster, one task per frame, and returns the files
    written. ``frames[i]`` changes the scene for frame ``i``: ``{"camera": {...},
    "instances": {index: matrix}}`` (camera entries as :meth:`canopy_rt.Scene.camera`
    takes them; mesh instances moved by 4x4 or 3x4 matrices, numbered as they were
    placed: ``add_mesh`` places one, ``add_instance`` returns its number), either may be
    left out.
    ``output`` names each frame's file by its number: ``"frames/f{frame:04d}.exr"``
    (``.png`` or ``.exr``). Each frame is the image :func:`canopy_rt.render` gives with
    those changes, written atomically by the driver as it arrives; frames whose file
    is already there are skipped, so running again after a failure renders only the
    rest. ``progress(done, total)`` is called as frames are written. ``allow_paths``
    is as for :func:`render`."""
    given = _render_options(locals())
    allow_paths = [os.path.abspath(p) for p in allow_paths]
    info = _described(scene, allow_paths)
    changes = [_frame_changes(i, f, info.counts["instances"]) for i, f in enumerate(frames)]
    try:
        paths = [str(output).format(frame=i) for i in range(len(changes))]
    except (KeyError, IndexError, ValueError) as e:
        raise ValueError(f"output {output!r} must name frames by {{frame}}: {e}") from None
    if len(set(paths)) != len(paths):
        raise ValueError(f"output {output!r} gives frames the same file: put {{frame}} in it")
    if int(threads_per_task) < 1:
        raise ValueError(f"threads_per_task must be at least 1, not {threads_per_task}")
    if device not in ("cpu", "gpu"):
        raise ValueError(f'device must be "cpu" or "gpu", not {device!r}')
    bundle = _bundle(scene, info)
    options = dict(given, threads=int(threads_per_task))
    if allow_paths:
        options["allow_paths"] = allow_paths
    todo = [i for i, path in enumerate(paths) if not os.path.exists(path)]
    done = len(paths) - len(todo)
    if progress is not None and done:
        progress(done, len(paths))
    if not todo:
        return paths
    for path in {os.path.dirname(os.path.abspath(paths[i])) for i in todo}:
        os.makedirs(path, exist_ok=True)
    inputs = _inputs(scene, info)
    for i in todo:
        _canopy.check_output(paths[i], f"frame {i}", "image", inputs)

    # A frame is a whole image (no region) with its changes.
    ray, task = _tasks(render_tile, address, threads_per_task, device)
    bundle_ref = ray.put(bundle)
    pending = {task.remote(bundle_ref, None, dict(options, **changes[i]), __version__): i
               for i in todo}

    def take(i, frame: np.ndarray) -> None:
        nonlocal done
        write_image(paths[i], frame)  # atomic: no half-written frame
        done += 1
        if progress is not None:
            progress(done, len(paths))

    _as_they_finish(ray, pending, take)
    return paths


def _canopy_command(canopy_bin: Optional[str]) -> str:
    """The canopy command line program: given, else $CANOPY_BIN, else `canopy` on PATH."""
    return canopy_bin or os.environ.get("CANOPY_BIN") or "canopy"


def bench_cell(canopy_bin: str, scene: int, method: str, arguments: List[str], version: str) -> dict:
    """One cell of ``canopy bench paper`` (a scene, a method, one run), as a Ray task runs
    it: the measurement and the run's settings line, from the node's own canopy."""
    import subprocess

    _same_version(version)
    with tempfile.TemporaryDirectory(prefix="canopy-cell-") as out:
        command = [canopy_bin, "bench", "paper", "--scenes", str(scene), "--method", method,
                   "--runs", "1", "--json-only", "--out", out, *arguments]
        try:
            run = subprocess.run(command, capture_output=True, text=True)
        except OSError as e:
            raise RuntimeError(f"cannot run {canopy_bin} on this node: {e}") from None
        if run.returncode != 0:
            raise RuntimeError(f"{' '.join(command)} failed: {run.stderr.strip()}")
        with open(os.path.join(out, "results.json")) as f:
            record = json.load(f)
    return {"measurement": record["measurements"][0], "settings": record["settings"]}


def bench_paper(
    out,
    *,
    scenes: Sequence[int] = (1, 2, 3, 4, 5, 6),
    methods: str = "all",
    runs: int = 6,
    size: Tuple[int, int] = (480, 480),
    spp: int = 128,
    integrator: str = "bsdf",
    fast_triangles: bool = False,
    threads_per_task: int = 1,
    canopy_bin: Optional[str] = None,
    address: Optional[str] = None,
    progress: Optional[Callable[[int, int], None]] = None,
) -> str:
    """``canopy bench paper`` with its cells (scene x method x run) as Ray tasks, one
    table out: every node runs its own ``canopy`` program (``canopy_bin``, else
    $CANOPY_BIN, else ``canopy`` on its PATH) for one render of one method on one scene;
    the driver merges the runs of each cell in run order into ``out/results.json`` and
    makes the tables, plots and pictures from it (``canopy bench paper --from``).
    Returns the path of ``results.md``. A cell's time is one task's render, on a node
    shared with other tasks: compare methods of one run, as the tables do.
    ``fast_triangles`` renders every cell with the fast triangle test
    (``canopy bench paper --fast-triangles``)."""
    import subprocess

    program = _canopy_command(canopy_bin)
    scenes = [int(n) for n in scenes]
    if not scenes or any(not 1 <= n <= 6 for n in scenes):
        raise ValueError(f"scenes are numbers 1 to 6, not {scenes}")
    if int(runs) < 1:
        raise ValueError(f"runs must be at least 1, not {runs}")
    try:
        listing = subprocess.run([program, "bench", "paper", "--list-methods", "--methods", methods],
                                 capture_output=True, text=True)
    except OSError as e:
        raise ValueError(f"cannot run {program} (give canopy_bin= or set CANOPY_BIN): {e}") from None
    if listing.returncode != 0:
        raise ValueError(f"{program} bench paper --methods {methods}: {listing.stderr.strip()}")
    labels = listing.stdout.splitlines()
    os.makedirs(str(out), exist_ok=True)
    record_path = os.path.join(str(out), "results.json")
    _canopy.check_output(record_path, "benchmark results", "data")
    arguments = ["--size", f"{int(size[0])}x{int(size[1])}", "--spp", str(int(spp)),
                 "--integrator", str(integrator), "--threads", str(int(threads_per_task))]
    if fast_triangles:
        arguments.append("--fast-triangles")

    ray, task = _tasks(bench_cell, address, threads_per_task)
    cells = [(n, label, run) for n in scenes for label in labels for run in range(int(runs))]
    pending = {task.remote(program, n, label, arguments, __version__): (n, label, run)
               for n, label, run in cells}
    found: Dict[Tuple[int, str, int], dict] = {}

    def take(cell, result: dict) -> None:
        found[cell] = result
        if progress is not None:
            progress(len(found), len(cells))

    _as_they_finish(ray, pending, take)

    measurements = []
    for n in scenes:
        none_mean = None
        for label in labels:
            results = [found[(n, label, run)]["measurement"] for run in range(int(runs))]
            seconds = [r["seconds"][0] for r in results]
            mean = sum(seconds) / len(seconds)
            std = (sum((s - mean) ** 2 for s in seconds) / (len(seconds) - 1)) ** 0.5 if len(seconds) > 1 else 0.0
            merged = dict(results[0], seconds=seconds, mean_s=mean, std_s=std,
                          build_ms=sum(r["build_ms"] for r in results) / len(results),
                          mrays_per_s=results[0]["rays"] / max(mean, 1e-9) / 1e6)
            if merged["builder"] == "none":
                none_mean = mean
            merged["speedup"] = None if none_mean is None else none_mean / mean
            measurements.append(merged)
    first = found[cells[0]]["settings"]
    settings = first.replace("1 runs per measurement", f"{int(runs)} runs per measurement (as Ray tasks)")
    record = {
        "settings": settings,
        "command": f"canopy_rt.distributed.bench_paper(scenes={scenes}, methods={methods!r}, "
                   f"runs={int(runs)}, size={tuple(size)}, spp={int(spp)}, integrator={integrator!r}, "
                   f"fast_triangles={bool(fast_triangles)})",
        "config": {"width": int(size[0]), "height": int(size[1]), "spp": int(spp), "runs": int(runs),
                   "threads": int(threads_per_task),
                   "triangles": "fast" if fast_triangles else "watertight"},
        "measurements": measurements,
    }
    _canopy.write_file(record_path, json.dumps(record, indent=2).encode())
    tables = subprocess.run([program, "bench", "paper", "--from", record_path, "--out", str(out)],
                            capture_output=True, text=True)
    if tables.returncode != 0:
        raise RuntimeError(f"{program} bench paper --from {record_path}: {tables.stderr.strip()}")
    return os.path.join(str(out), "results.md")


def _parser():
    """The command line's parser: canopy's render options as ``canopy render``'s flags
    (each task's threads are ``--threads-per-task``)."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m canopy_rt.distributed",
                                     description="Render a canopy scene on a Ray cluster.")
    commands = parser.add_subparsers(dest="command", required=True)
    image_command = commands.add_parser("render", help="render a scene, tiles as Ray tasks")
    frames_command = commands.add_parser(
        "frames", help="render an animation, one Ray task per frame")
    for command in (image_command, frames_command):
        command.add_argument("scene", help="built-in scene name, scene file, mesh or glTF model")
        command.add_argument("--spp", type=int)
        command.add_argument("--size", help="WxH")
        command.add_argument("--seed", type=int)
        command.add_argument("--depth", type=int, dest="max_depth")
        command.add_argument("--integrator", choices=["path", "bsdf"])
        command.add_argument("--no-roulette", dest="russian_roulette", action="store_const",
                             const=False, help="never end paths early by Russian roulette")
        command.add_argument("--sampler", help="sobol or independent")
        command.add_argument("--bvh", default="binned-sah", help="BVH builder (canopy builders)")
        command.add_argument("--width", type=int, default=8, help="children per node: 2, 4 or 8")
        command.add_argument("--max-leaf-size", type=int)
        command.add_argument("--fast-triangles", action="store_true",
                             help="triangles without the watertight test's double-precision step")
        command.add_argument("--schedule", default="wavefront", help="wavefront or depth")
        command.add_argument("--device", choices=["cpu", "gpu"], default="cpu")
        command.add_argument("--threads-per-task", type=int, default=1)
        command.add_argument("--address", help="Ray cluster address ('auto': this machine's "
                             "cluster); none starts a local Ray")
        command.add_argument("--allow-path", action="append", default=[], metavar="DIR",
                             help="a folder the scene may also read files from (a scene reads "
                             "only its own folder's files otherwise); repeat for several")
    image_command.add_argument("-o", "--output", required=True,
                               help=".png or .exr, written atomically")
    image_command.add_argument("--tile", type=int, default=64, help="tile size in pixels (64)")
    image_command.add_argument("--samples-per-task", type=int,
                               help="split each tile's samples into tasks of this many too")
    image_command.add_argument("--resume-dir", help="keep finished tiles here; run again with "
                               "the same arguments to render only the missing ones")
    image_command.add_argument("--denoise", action="store_true",
                               help="denoise the whole image with Open Image Denoise once the tiles are in")
    frames_command.add_argument("--frames", required=True,
                                help='JSON list of frames: [{"camera": {"look_from": [x, y, z]}, '
                                '"instances": {"0": 4x4 matrix}}, ...]')
    frames_command.add_argument("-o", "--output", required=True,
                                help="file of each frame by its number, as f{frame:04d}.exr; "
                                "frames already there are skipped")
    return parser


def main(argv=None) -> int:
    """``python -m canopy_rt.distributed render SCENE -o IMAGE [options]``, or
    ``... frames SCENE --frames FRAMES.json -o 'f{frame:04d}.exr' [options]``."""
    import sys

    parser = _parser()
    args = parser.parse_args(argv)
    size = None
    if args.size:
        try:
            w, h = (int(v) for v in args.size.lower().split("x"))
            size = (w, h)
        except ValueError:
            parser.error(f"--size must be WxH, not {args.size}")
    unit = "tiles" if args.command == "render" else "frames"

    def show(done: int, total: int) -> None:
        print(f"\r{unit} {done}/{total}", end="" if done < total else "\n", file=sys.stderr)

    options = {name: getattr(args, name) for name in _canopy.RENDER_OPTIONS if name != "threads"}
    common = dict(options, size=size, threads_per_task=args.threads_per_task,
                  address=args.address, progress=show, allow_paths=args.allow_path)
    try:
        if args.command == "render":
            render(args.scene, tile=args.tile, samples_per_task=args.samples_per_task,
                   resume_dir=args.resume_dir, output=args.output, denoise=args.denoise, **common)
            print(f"image       {args.output}", file=sys.stderr)
        else:
            try:
                with open(args.frames) as f:
                    frames = json.load(f)
            except json.JSONDecodeError as e:
                raise ValueError(f"{args.frames}: not JSON: {e}") from None
            if not isinstance(frames, list):
                raise ValueError(f"{args.frames}: a list of frames, not {type(frames).__name__}")
            paths = render_frames(args.scene, frames, args.output, **common)
            print(f"frames      {len(paths)}: {paths[0] if paths else ''} ...", file=sys.stderr)
    except (ValueError, TypeError, OSError, RuntimeError, ImportError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
