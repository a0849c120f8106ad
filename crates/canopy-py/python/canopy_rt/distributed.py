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
cluster this machine belongs to). A task whose worker dies is run again by Ray.

With ``resume_dir=``, every finished tile is kept there as an EXR file (written
atomically, its float32 pixels exact) beside a record of the scene and settings; a driver
started again with the same arguments renders only the tiles that are missing, and
refuses a directory that holds another render's tiles.

Not yet: scenes built in Python (:class:`canopy_rt.Scene`), ranges of samples, animations.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np

from . import Scene, __version__, load_scene, read_image, scenes, write_image
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


def _bundle(scene: str) -> Tuple[str, Dict[str, bytes]]:
    """The scene as tasks receive it: its name or absolute path, and the bytes of every
    file it reads by absolute path (none for a built-in scene)."""
    info = load_scene(scene)  # raises here, before any work, when the scene is bad
    if scene in scenes():  # a built-in scene wins over a file of the same name, as in load_scene
        return scene, {}
    files = {}
    for path in [scene, *info.inputs]:
        path = os.path.abspath(path)
        with open(path, "rb") as f:
            files[path] = f.read()
    return os.path.abspath(scene), files


# Per worker process: the directory a bundle's files were written to, by the bundle's key.
_written: Dict[str, str] = {}


def _materialize(source: str, files: Dict[str, bytes]) -> str:
    """Where `source` is on this worker: its files written once into a private
    directory, under their absolute paths, so that relative references still resolve."""
    if not files:
        return source
    digest = hashlib.sha256()
    for path in sorted(files):
        digest.update(path.encode())
        digest.update(hashlib.sha256(files[path]).digest())
    key = digest.hexdigest()
    root = _written.get(key)
    if root is None:
        root = tempfile.mkdtemp(prefix=f"canopy-{key[:12]}-")
        for path, data in files.items():
            target = os.path.join(root, os.path.splitdrive(path)[1].lstrip("/\\"))
            os.makedirs(os.path.dirname(target), exist_ok=True)
            with open(target, "wb") as f:
                f.write(data)
        _written[key] = root
    return os.path.join(root, os.path.splitdrive(source)[1].lstrip("/\\"))


def render_tile(bundle, region: _Region, options: dict, version: str) -> np.ndarray:
    """One tile, as a Ray task runs it (callable directly too): the driver's canopy
    version must be this worker's."""
    if version != __version__:
        raise RuntimeError(
            f"canopy_rt {__version__} on this worker, {version} on the driver: install the "
            "same version on every node")
    source, files = bundle
    return render_locally(_materialize(source, files), region=region, **options)


class _TileStore:
    """Finished tiles of one render kept in a directory: `render.json` says which
    render (scene file contents, settings, tiling), each tile is `tile-X-Y.exr`."""

    def __init__(self, directory, record: dict):
        self.directory = str(directory)
        os.makedirs(self.directory, exist_ok=True)
        path = os.path.join(self.directory, "render.json")
        if os.path.exists(path):
            with open(path) as f:
                found = json.load(f)
            if found != record:
                raise ValueError(f"{self.directory} holds the tiles of another render "
                                 "(other scene, settings or tiling): give an empty directory")
        else:
            temporary = path + ".tmp"
            with open(temporary, "w") as f:
                json.dump(record, f)
            os.replace(temporary, path)

    def path(self, region: _Region) -> str:
        return os.path.join(self.directory, f"tile-{region[0]}-{region[1]}.exr")

    def load(self, region: _Region) -> Optional[np.ndarray]:
        path = self.path(region)
        if not os.path.exists(path):
            return None
        tile = read_image(path)
        return tile if tile.shape == (region[3], region[2], 3) else None

    def keep(self, region: _Region, tile: np.ndarray) -> None:
        write_image(self.path(region), tile)  # atomic: a killed driver leaves no half tile


def render(
    scene,
    *,
    spp: Optional[int] = None,
    size: Optional[Tuple[int, int]] = None,
    seed: Optional[int] = None,
    max_depth: Optional[int] = None,
    integrator: Optional[str] = None,
    russian_roulette: Optional[bool] = None,
    bvh: str = "binned-sah",
    width: int = 8,
    tile: int = 64,
    threads_per_task: int = 1,
    address: Optional[str] = None,
    progress: Optional[Callable[[int, int], None]] = None,
    resume_dir=None,
) -> np.ndarray:
    """Renders ``scene`` on a Ray cluster: the same linear float32 (height, width, 3)
    image as :func:`canopy_rt.render` with the same settings, bit for bit. The image is
    split into tiles of ``tile`` x ``tile`` pixels, one Ray task each, each task using
    ``threads_per_task`` threads (and asking Ray for as many CPUs). ``progress(done,
    total)`` is called on the driver as tiles finish (tiles found in ``resume_dir`` count
    as finished at the start)."""
    if isinstance(scene, Scene):
        raise TypeError("a Scene built in Python cannot be shipped to a cluster yet: "
                        "render a scene file, mesh or glTF model")
    if int(tile) < 1:
        raise ValueError(f"tile must be at least 1 pixel, not {tile}")
    if int(threads_per_task) < 1:
        raise ValueError(f"threads_per_task must be at least 1, not {threads_per_task}")
    scene = str(scene)
    bundle = _bundle(scene)
    settings = load_scene(scene).settings
    image_width, image_height = (int(size[0]), int(size[1])) if size else (settings["width"], settings["height"])
    options = dict(spp=spp, size=(image_width, image_height), seed=seed, max_depth=max_depth,
                   integrator=integrator, russian_roulette=russian_roulette, bvh=bvh,
                   width=width, threads=int(threads_per_task))

    regions = tiles(image_width, image_height, int(tile))
    image = np.zeros((image_height, image_width, 3), np.float32)
    store = None
    if resume_dir is not None:
        digest = hashlib.sha256()
        for path in sorted(bundle[1]):
            digest.update(path.encode() + hashlib.sha256(bundle[1][path]).digest())
        record = dict(scene=bundle[0], files=digest.hexdigest(), tile=int(tile),
                      version=__version__, **{k: v for k, v in options.items() if k != "threads"})
        store = _TileStore(resume_dir, json.loads(json.dumps(record)))
    todo = []
    for region in regions:
        kept = store.load(region) if store else None
        if kept is None:
            todo.append(region)
        else:
            x, y, w, h = region
            image[y:y + h, x:x + w] = kept
    done = len(regions) - len(todo)
    if progress is not None and done:
        progress(done, len(regions))
    if not todo:
        return image

    ray = _ray()
    if not ray.is_initialized():
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    task = ray.remote(num_cpus=int(threads_per_task), max_retries=3)(render_tile)
    bundle_ref = ray.put(bundle)
    pending = {task.remote(bundle_ref, region, options, __version__): region for region in todo}
    try:
        while pending:
            finished, _ = ray.wait(list(pending), num_returns=1)
            for ref in finished:
                region = pending.pop(ref)
                x, y, w, h = region
                image[y:y + h, x:x + w] = ray.get(ref)
                if store:
                    store.keep(region, image[y:y + h, x:x + w])
                done += 1
                if progress is not None:
                    progress(done, len(regions))
    finally:
        for ref in pending:
            ray.cancel(ref)
    return image


def main(argv=None) -> int:
    """``python -m canopy_rt.distributed render SCENE -o IMAGE [options]``."""
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog="python -m canopy_rt.distributed",
                                     description="Render a canopy scene on a Ray cluster.")
    commands = parser.add_subparsers(dest="command", required=True)
    command = commands.add_parser("render", help="render a scene, tiles as Ray tasks")
    command.add_argument("scene", help="built-in scene name, scene file, mesh or glTF model")
    command.add_argument("-o", "--output", required=True, help=".png or .exr, written atomically")
    command.add_argument("--spp", type=int)
    command.add_argument("--size", help="WxH")
    command.add_argument("--seed", type=int)
    command.add_argument("--depth", type=int, dest="max_depth")
    command.add_argument("--integrator", choices=["path", "bsdf"])
    command.add_argument("--tile", type=int, default=64, help="tile size in pixels (64)")
    command.add_argument("--threads-per-task", type=int, default=1)
    command.add_argument("--address", help="Ray cluster address ('auto': this machine's "
                         "cluster); none starts a local Ray")
    command.add_argument("--resume-dir", help="keep finished tiles here; run again with the "
                         "same arguments to render only the missing ones")
    args = parser.parse_args(argv)
    size = None
    if args.size:
        try:
            w, h = (int(v) for v in args.size.lower().split("x"))
            size = (w, h)
        except ValueError:
            parser.error(f"--size must be WxH, not {args.size}")

    def show(done: int, total: int) -> None:
        print(f"\rtiles {done}/{total}", end="" if done < total else "\n", file=sys.stderr)

    try:
        image = render(args.scene, spp=args.spp, size=size, seed=args.seed,
                       max_depth=args.max_depth, integrator=args.integrator, tile=args.tile,
                       threads_per_task=args.threads_per_task, address=args.address,
                       progress=show, resume_dir=args.resume_dir)
        write_image(args.output, image)
    except (ValueError, TypeError, OSError, RuntimeError, ImportError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    print(f"image       {args.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
