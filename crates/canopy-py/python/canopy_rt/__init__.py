"""canopy: a BVH laboratory and path tracer, from Python.

Build a BVH over a triangle mesh (or boxes) from numpy arrays and trace batches of rays
through it, Embree-style; render canopy's scenes to numpy images.

>>> import numpy as np, canopy_rt as canopy
>>> vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
>>> bvh = canopy.Bvh(vertices, np.array([[0, 1, 2]]))
>>> hits = bvh.intersect([[0.2, 0.2, 1.0]], [[0, 0, -1]])
>>> float(hits.t[0]), int(hits.prim[0])
(1.0, 0)

Every call that does real work releases the GIL and runs in parallel (all cores, or
``threads=n``). Arguments are converted to the dtypes canopy uses (float32 coordinates,
int64 indices) and checked: a wrong shape, a NaN, an index past the vertex count raise
``ValueError``/``TypeError`` naming the argument.
"""

from __future__ import annotations

import os
from typing import Callable, List, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from . import _canopy
from ._arguments import _fault, naming_arguments, naming_arguments_of_methods
from .scene import Scene, _transform, dielectric, emissive, eval_material, lambertian, metal, pbr
from .ray_scene import ClosestPoints, RayHitLists, RayHits, RayScene
from .view import Viewer

__version__: str = _canopy.__version__

__all__ = [
    "Bvh",
    "Hits",
    "RayHits",
    "RayScene",
    "ClosestPoints",
    "RayHitLists",
    "Scene",
    "SceneInfo",
    "dielectric",
    "emissive",
    "eval_material",
    "lambertian",
    "metal",
    "pbr",
    "builders",
    "scenes",
    "devices",
    "example_mesh",
    "load_mesh",
    "load_scene",
    "read_image",
    "render",
    "RENDER_OPTIONS",
    "view",
    "Viewer",
    "denoise",
    "__version__",
    "write_image",
]

SceneInfo = _canopy.SceneInfo


class Hits(NamedTuple):
    """Closest hits of a batch of rays, one row per ray."""

    t: np.ndarray
    """(n,) float32 distance along the ray (in units of its direction's length); inf on a miss."""
    prim: np.ndarray
    """(n,) int64 index of the triangle (face row) or box hit; -1 on a miss."""
    uv: np.ndarray
    """(n, 2) float32 barycentric weights of the triangle's vertices 1 and 2 (0 for boxes and misses)."""


def builders() -> list:
    """The names of the BVH builders, e.g. ``["sort-x", ..., "binned-sah", ...]``."""
    return _canopy.builders()


def _array(value, name: str, dtype, ndim: int, shape_text: str) -> np.ndarray:
    """``value`` as a C-contiguous array of ``dtype`` with ``ndim`` dimensions."""
    try:
        array = np.asarray(value)
    except Exception as e:  # ragged lists and the like
        raise TypeError(f"{name} must be an array of shape {shape_text}: {e}") from None
    if array.dtype == object or not (
        np.issubdtype(array.dtype, np.number) or array.dtype == np.bool_
    ):
        raise TypeError(f"{name} must be numeric with shape {shape_text}, not dtype {array.dtype}")
    if np.issubdtype(dtype, np.integer) and array.size:
        if not np.issubdtype(array.dtype, np.integer):
            if not (np.all(np.isfinite(array)) and np.all(array == np.round(array))):
                raise TypeError(f"{name} must hold integer indices, not dtype {array.dtype} with fractions")
        elif array.dtype.kind == "u" and array.max() > np.iinfo(np.int64).max:
            raise ValueError(f"{name} holds index {array.max()}, beyond any vertex count")
    if array.ndim != ndim:
        raise ValueError(f"{name} must have shape {shape_text}, not {array.shape}")
    # A copy only when needed: other dtypes, strided views, unaligned buffers.
    return np.require(array, dtype=dtype, requirements=["C_CONTIGUOUS", "ALIGNED"])


def _per_ray(value, name: str, n: int):
    """A number for every ray (passed as it is), or a (n,) float32 array."""
    array = np.asarray(value, dtype=np.float32)
    if array.ndim == 0:
        return float(array)
    if array.shape != (n,):
        raise ValueError(f"{name} must be a number or have shape ({n},), not {array.shape}")
    return np.require(array, requirements=["C_CONTIGUOUS", "ALIGNED"])


def _ray_batch(origins, directions, tnear, tfar):
    """Checked (origins, directions, tnear, tfar) for the native calls: ``origins`` and
    ``directions`` (n, 3) each, or, with ``directions`` None, ``origins`` (n, 6) rows of
    origin then direction (Open3D's ray tensors), passed as they are (the native side
    reads both from the rows; splitting 1M rays into two copies took 9 ms)."""
    if directions is None:
        rays = _array(origins, "rays", np.float32, 2, "(n, 6)")
        if rays.shape[1] != 6:
            raise ValueError(
                f"rays without directions must have shape (n, 6) (origin, direction), not {rays.shape}"
            )
        origins = rays
    else:
        origins = _array(origins, "origins", np.float32, 2, "(n, 3)")
        directions = _array(directions, "directions", np.float32, 2, "(n, 3)")
    n = origins.shape[0]
    return origins, directions, _per_ray(tnear, "tnear", n), _per_ray(tfar, "tfar", n)


def _options(builder, width, max_leaf_size, sah_traversal, sah_intersection, ploc_radius, max_duplication,
             optimize, threads, triangles):
    if not isinstance(builder, str):
        raise TypeError(f"builder must be a name (see canopy_rt.builders()), not {builder!r}")
    if triangles not in ("watertight", "fast"):
        raise ValueError(f"triangles must be 'watertight' or 'fast', not {triangles!r}")
    return dict(
        builder=builder,
        width=int(width),
        max_leaf_size=max_leaf_size,
        sah_traversal=sah_traversal,
        sah_intersection=sah_intersection,
        ploc_radius=ploc_radius,
        max_duplication=max_duplication,
        optimize=None if optimize is None else float(optimize),
        threads=threads,
        triangles=triangles,
    )


@naming_arguments_of_methods
class Bvh:
    """A bounding volume hierarchy over a triangle mesh or over boxes.

    ``Bvh(vertices, faces)``: ``vertices`` (V, 3) float coordinates, ``faces`` (F, 3)
    integer vertex indices. ``Bvh.from_boxes(boxes)``: (N, 2, 3) min and max corners.

    ``builder`` names how the tree is built (``canopy.builders()``: ``binned-sah`` by
    default, ``sweep-sah`` for the best trees, ``lbvh`` for the fastest build, the
    report's ``agglomerative``, ``ploc``, ``sbvh`` with spatial splits ...; or ``none``, a plain loop over every
    primitive, the reference every tree is tested against); ``width`` is the layout: 2 (binary), 4 or 8
    (SIMD wide nodes with triangles packed in the leaves; the fastest). The other options
    are the builders' (``max_leaf_size``: 4 by default, 8 for a 4- or 8-wide tree over
    triangles, whose leaves hold up to two packs of four; the SAH costs, ``ploc_radius``, and
    ``max_duplication``, the fraction of extra references ``sbvh`` may make); ``optimize=s``
    improves the tree by reinsertion for ``s`` seconds before it is laid out.

    ``triangles="fast"`` tests triangles without the watertight test's double-precision
    step for rays that pass within rounding of an edge (Embree's default mode makes the
    same trade): fewer instructions per ray, and such a ray may hit every triangle at
    the edge, not only the one the exact signs give. ``"watertight"`` is the default.

    A ``Bvh`` pickles (for ``multiprocessing``, Ray's object store): the pickle holds
    its primitives and options, and loading builds the tree again.
    """

    def __init__(
        self,
        vertices,
        faces,
        builder: str = "binned-sah",
        width: int = 8,
        *,
        max_leaf_size: Optional[int] = None,
        sah_traversal: Optional[float] = None,
        sah_intersection: Optional[float] = None,
        ploc_radius: Optional[int] = None,
        max_duplication: Optional[float] = None,
        optimize: Optional[float] = None,
        threads: Optional[int] = None,
        triangles: str = "watertight",
    ):
        vertices = _array(vertices, "vertices", np.float32, 2, "(V, 3)")
        faces = _array(faces, "faces", np.int64, 2, "(F, 3)")
        options = _options(
            builder, width, max_leaf_size, sah_traversal, sah_intersection, ploc_radius, max_duplication,
            optimize, threads, triangles,
        )
        self._native = _canopy.Bvh(vertices, faces, **options)
        self._options = options

    @classmethod
    def from_boxes(
        cls,
        boxes,
        builder: str = "binned-sah",
        width: int = 8,
        *,
        max_leaf_size: Optional[int] = None,
        sah_traversal: Optional[float] = None,
        sah_intersection: Optional[float] = None,
        ploc_radius: Optional[int] = None,
        max_duplication: Optional[float] = None,
        optimize: Optional[float] = None,
        threads: Optional[int] = None,
    ) -> "Bvh":
        """A BVH over axis-aligned boxes, (N, 2, 3): a ray hits a box where it enters it
        (or, starting inside, where it leaves)."""
        boxes = _array(boxes, "boxes", np.float32, 3, "(N, 2, 3)")
        self = cls.__new__(cls)
        options = _options(
            builder, width, max_leaf_size, sah_traversal, sah_intersection, ploc_radius, max_duplication,
            optimize, threads, "watertight",
        )
        self._native = _canopy.Bvh.from_boxes(boxes, **options)
        self._options = options
        return self

    def __reduce__(self):
        # A pickle holds the mesh (or the boxes) and the options; unpickling builds the
        # tree again (with all cores), which gives the same answers: ties never depend on
        # the tree. A serialised tree would load faster but make the pickle three times
        # larger, and the unsafe traversal would have to trust its bytes
        # (docs/performance.md). The mesh keeps its vertices shared, so that the copy
        # takes `set_vertices` as the original does.
        options = {k: v for k, v in self._options.items() if k != "threads"}
        mesh = self._native.mesh()
        if mesh is not None:
            return _unpickle_bvh, ("mesh", mesh, options)
        # Boxes take no triangle mode.
        options.pop("triangles", None)
        kind, primitives = self._native.primitives()
        return _unpickle_bvh, (kind, primitives, options)

    def set_vertices(self, vertices, *, threads: Optional[int] = None) -> None:
        """Moves the mesh's vertices to ``vertices`` ((V, 3), as many as it has; the faces
        stay) and refits the tree: every box recomputed from the moved triangles, the
        tree's shape kept (cheaper than a build; a tree refitted over a large motion traces
        slower than a new one). Refused with ValueError for a ``Bvh`` over boxes, for
        another vertex count, and for a tree with spatial splits (``sbvh``), whose leaves
        hold parts of triangles; a refused call changes nothing."""
        vertices = _array(vertices, "vertices", np.float32, 2, "(V, 3)")
        self._native.set_vertices(vertices, threads)

    @property
    def primitive_count(self) -> int:
        return self._native.primitive_count

    @property
    def builder(self) -> str:
        return self._native.builder

    @property
    def width(self) -> int:
        return self._native.width

    def stats(self) -> dict:
        """SAH cost (root area 1), nodes, leaves, depth, leaf sizes, memory and build time."""
        return self._native.stats()

    def validate(self) -> None:
        """Checks the tree's invariants; raises ValueError naming the first one broken."""
        self._native.validate()

    def epo(self) -> float:
        """Effective parallel overlap (Aila, Karras & Laine 2013): what SAH leaves out, the
        surface of other subtrees inside each node's box, priced at the node's cost and
        relative to the whole surface. Seconds on a million triangles."""
        return self._native.epo()

    def intersect(
        self,
        origins,
        directions=None,
        tnear=0.0,
        tfar=np.inf,
        *,
        threads: Optional[int] = None,
        coherent: bool = False,
    ) -> Hits:
        """Closest hits of the rays ``origin + t * direction``, ``tnear <= t <= tfar``.

        ``origins`` and ``directions`` are (n, 3) (or ``origins`` alone (n, 6), each row
        an origin then a direction, as Open3D's rays); ``tnear`` and ``tfar`` numbers or (n,).
        Directions need not be unit length (``t`` is in their units). Ties go to the
        lower primitive index, so every builder and width gives the same answer.

        ``coherent=True`` says that neighbouring rays start near each other and run in
        similar directions (a camera's rays row by row, or many rays from one point): they
        are then traced 16 at a time as packets, which is faster for such rays and slower
        for scattered ones. The answers are the same either way.
        """
        rays = _ray_batch(origins, directions, tnear, tfar)
        t, prim, uv = self._native.intersect(*rays, threads, coherent)
        return Hits(t, prim, uv)

    def occluded(
        self,
        origins,
        directions=None,
        tnear=0.0,
        tfar=np.inf,
        *,
        threads: Optional[int] = None,
        coherent: bool = False,
    ) -> np.ndarray:
        """(n,) bool: whether anything lies on each ray within ``[tnear, tfar]`` (any hit,
        not the closest: faster, for shadow and visibility rays). ``coherent`` as for
        :meth:`intersect` (shadow rays from neighbouring points towards one light)."""
        rays = _ray_batch(origins, directions, tnear, tfar)
        return self._native.occluded(*rays, threads, coherent)

    def __repr__(self) -> str:
        return repr(self._native)


def _unpickle_bvh(kind: str, primitives, options: dict) -> Bvh:
    if kind == "boxes":
        return Bvh.from_boxes(primitives, **options)
    if kind == "mesh":
        vertices, faces = primitives
        return Bvh(vertices, faces, **options)
    # Each triangle's own three vertices: the same triangles, in the same order.
    faces = np.arange(3 * len(primitives), dtype=np.int64).reshape(-1, 3)
    return Bvh(primitives.reshape(-1, 3), faces, **options)


def scenes() -> list:
    """The names of the built-in scenes (``paper-1`` … ``paper-6``, ``cornell``, …), in the
    order ``canopy scenes`` lists them; any of them is a ``scene`` for :func:`render`."""
    return _canopy.scenes()


def devices() -> List[str]:
    """The GPU adapters that ``device="gpu"`` can render on, described; empty when
    there is none (``canopy devices`` on the command line)."""
    return _canopy.devices()


def example_mesh() -> Tuple[np.ndarray, np.ndarray]:
    """The vertices (V, 3) float32 and triangles (F, 3) int64 of a small Stanford bunny
    (3674 triangles, about 10 units tall, +y up) shipped with the package, for examples
    and first tries: the same file as canopy's scenes use (``scenes/meshes/bunny.ply``)."""
    from pathlib import Path

    return load_mesh(Path(__file__).parent / "data" / "bunny.ply")


def load_mesh(path) -> Tuple[np.ndarray, np.ndarray]:
    """The vertices (V, 3) float32 and triangles (F, 3) int64 of an OBJ or PLY file, read
    as canopy's scenes read them (polygons fan-triangulated)."""
    return _canopy.load_mesh(str(path))


def load_scene(scene: str, *, allow_paths: Sequence = ()) -> SceneInfo:
    """Loads a built-in scene by name (``"cornell"``), a scene file, or an OBJ/PLY mesh,
    and describes it: ``name``, ``settings``, ``counts``, ``bounds``, ``warnings``.

    A scene reads only the files in its own folder (and below): a mesh, model or map it
    names elsewhere (``../``, an absolute path, a link out) is refused unless it lies in
    one of the folders ``allow_paths``."""
    return _canopy.load_scene(str(scene), [str(p) for p in allow_paths])


#: The names of canopy's render options: one type in the library (the settings
#: ``canopy render``'s flags, :func:`render`'s, :func:`view`'s and
#: :func:`canopy_rt.distributed.render`'s keywords and the viewer's page all set).
RENDER_OPTIONS: Tuple[str, ...] = tuple(_canopy.RENDER_OPTIONS)


# The render options held in 64 bits (the other integers are 32-bit).
_WIDE_OPTIONS = frozenset({"seed", "threads"})


def _render_options(given: dict) -> dict:
    """The render options among a function's arguments, those left as None dropped;
    a size is made a pair of ints. An integer no option can hold is named as
    :func:`naming_arguments` names it (the native error would say only "overflow")."""
    options = {name: given[name] for name in RENDER_OPTIONS if given.get(name) is not None}
    for name, value in options.items():
        fault = _fault(value)
        if fault is not None and (fault[0] < 2 or name not in _WIDE_OPTIONS):
            raise ValueError(f"{name}={value!r} {fault[1]}")
    if "size" in options:
        size = options["size"]
        options["size"] = (int(size[0]), int(size[1]))
    return options


@naming_arguments
def render(
    scene=None,
    *,
    spp: Optional[int] = None,
    size: Optional[Tuple[int, int]] = None,
    seed: Optional[int] = None,
    max_depth: Optional[int] = None,
    integrator: Optional[str] = None,
    russian_roulette: Optional[bool] = None,
    sampler: Optional[str] = None,
    device: str = "cpu",
    bvh: str = "binned-sah",
    width: int = 8,
    max_leaf_size: Optional[int] = None,
    fast_triangles: Optional[bool] = None,
    threads: Optional[int] = None,
    schedule: str = "wavefront",
    progress: Optional[Callable[[int, int], None]] = None,
    region: Optional[Tuple[int, int, int, int]] = None,
    checkpoint=None,
    checkpoint_every: float = 60.0,
    resume=None,
    samples: Optional[Tuple[int, int]] = None,
    camera: Optional[dict] = None,
    instances: Optional[dict] = None,
    allow_paths: Sequence = (),
    aovs: Optional[Sequence[str]] = None,
    denoise: bool = False,
):
    """Renders a scene (built-in name, scene file or mesh, or a :class:`Scene` built in
    Python) to a linear float32 image of shape (height, width, 3), exactly as
    ``canopy render`` does (the same pixels as its EXR output). Settings left as None
    come from the scene. ``size`` is (width, height).

    ``device="gpu"`` renders on the first GPU adapter found (the CPU's image up to
    rounding). ``region=(x, y, width, height)`` renders only that rectangle: an image of
    that shape whose pixels are exactly those of the whole image.

    ``progress(done, total)`` is called after each sample per pixel; Ctrl-C (or an
    exception raised by ``progress``) stops the render after the sample in flight. With
    ``checkpoint=path`` the render is saved there every ``checkpoint_every`` seconds and
    when stopped; ``render(resume=path)`` continues it to the same image (a
    :class:`Scene` is given again: ``render(scene, resume=path)``).

    ``samples=(first, count)`` renders only samples ``first .. first + count`` of each
    pixel (instead of ``spp``) and returns their mean: ranges rendered apart (on
    several machines, say) weighted by their counts make the whole render's image, up
    to the rounding of the sums.

    ``camera`` moves the camera for this render (a dict of any of ``look_from``,
    ``look_at``, ``up``, ``vfov``, ``aperture``, ``focus_distance``, ``ortho_height``) and ``instances``
    moves mesh instances (``{index: 4x4 or 3x4 matrix}``): a frame of an animation.

    ``sampler`` is how each sample's random numbers are drawn: ``"sobol"`` (each
    pixel's samples spread evenly over the camera's and the first bounces' dimensions by
    scrambled Sobol points: less noise) or ``"independent"``.

    ``schedule`` is the order the CPU traces paths in: ``"wavefront"`` (many at a time,
    stage by stage) or ``"depth"`` (one at a time); the image is the same bit for bit.

    ``bvh`` (``"none"`` or a builder of :func:`builders`), ``width`` (children per node:
    2, 4 or 8) and ``max_leaf_size`` choose the tree; ``fast_triangles=True`` tests
    triangles without the watertight test's double-precision step (Embree's default
    mode: fewer instructions; a ray within rounding of a shared edge may hit every
    triangle there), on the CPU only. Left out, the test is watertight, or for
    ``resume=`` the mode the render was started in (which it keeps). The render options (``RENDER_OPTIONS``) are those
    ``canopy render`` takes as flags, by the same names.

    A scene file reads only the files in its own folder (and below); ``allow_paths``
    lists further folders its meshes, models and maps may come from.

    ``aovs`` (any of ``"albedo"``, ``"normal"``, ``"depth"``, ``"position"``, ``"id"``)
    also renders those images of the surfaces seen, and the call returns ``(image,
    {name: array})``: ``albedo``, ``normal`` and ``position`` of shape (height, width,
    3), ``depth`` (height, width), and for ``id`` the uint32 ``instance`` and
    ``primitive`` (height, width; 4294967295 where nothing is hit). Albedo and normal
    are those a denoiser takes (the first surface past mirrors and glass, averaged over
    the pixel's samples); depth, position and ids are of each pixel's first sample.

    ``denoise=True`` returns the image denoised by Open Image Denoise (see
    :func:`denoise`), guided by the albedo and normal it renders for it; it fails before
    rendering when OIDN is not installed.
    """
    options = _render_options(locals())
    if region is not None:
        region = tuple(int(v) for v in region)
        if len(region) != 4:
            raise ValueError(f"region must be (x, y, width, height), not {region!r}")
    return _canopy.render(
        None if scene is None else scene._native.native if isinstance(scene, Scene) else str(scene),
        options,
        progress=progress,
        region=region,
        checkpoint=None if checkpoint is None else str(checkpoint),
        checkpoint_every=float(checkpoint_every),
        resume=None if resume is None else str(resume),
        samples=None if samples is None else (int(samples[0]), int(samples[1])),
        camera=None if camera is None else dict(camera),
        instances=None if instances is None else {int(k): _transform(v) for k, v in instances.items()},
        allow_paths=[str(p) for p in allow_paths],
        aovs=None if aovs is None else ",".join(_aov_names(aovs)),
        denoise=bool(denoise),
        oidn_paths=_oidn_paths() if denoise else [],
    )


def _aov_names(aovs) -> List[str]:
    if isinstance(aovs, str):
        raise TypeError(f"aovs must be a list of names, such as ['albedo', 'normal'], not {aovs!r}")
    return [str(a) for a in aovs]


def _oidn_paths() -> List[str]:
    """The folder of Open Image Denoise's libraries in an installed ``pyoidn`` package
    (PyPI's wheel ships them), found without importing it; empty when there is none."""
    import importlib.util

    try:
        spec = importlib.util.find_spec("pyoidn")
    except (ImportError, ValueError):
        return []
    if spec is None or not spec.submodule_search_locations:
        return []
    return [os.path.join(folder, "oidn", "lib") for folder in spec.submodule_search_locations]


@naming_arguments
def denoise(
    color,
    albedo=None,
    normal=None,
    *,
    threads: Optional[int] = None,
    prefilter: bool = False,
) -> np.ndarray:
    """A noisy linear float32 (height, width, 3) image denoised by Intel Open Image
    Denoise 2, guided by the ``albedo`` and ``normal`` images (same shape; a normal
    needs an albedo) where given, as :func:`render` returns them with ``aovs=``.

    ``prefilter`` denoises the albedo and normal first and then uses them as clean
    guides (OIDN's advice where they are noisy: depth of field, glass; several times
    slower). OIDN is found through ``CANOPY_OIDN``, an
    installed ``pyoidn`` package, canopy's folder (``scripts/oidn.sh`` installs it
    there) or the system; when it is missing, a RuntimeError says how to install it."""
    color = _array(color, "color", np.float32, 3, "(height, width, 3)")
    albedo = None if albedo is None else _array(albedo, "albedo", np.float32, 3, "(height, width, 3)")
    normal = None if normal is None else _array(normal, "normal", np.float32, 3, "(height, width, 3)")
    return _canopy.denoise(color, albedo, normal, threads=threads, prefilter=bool(prefilter),
                           oidn_paths=_oidn_paths())


@naming_arguments
def view(
    scene,
    *,
    bind: str = "127.0.0.1:0",
    size: Optional[Tuple[int, int]] = None,
    spp: Optional[int] = None,
    max_depth: Optional[int] = None,
    seed: Optional[int] = None,
    integrator: Optional[str] = None,
    russian_roulette: Optional[bool] = None,
    sampler: Optional[str] = None,
    bvh: str = "binned-sah",
    width: Optional[int] = None,
    max_leaf_size: int = 4,
    fast_triangles: bool = False,
    schedule: str = "wavefront",
    device: str = "cpu",
    threads: Optional[int] = None,
    output_dir=".",
    allow_paths: Sequence = (),
    reload: bool = True,
) -> Viewer:
    """Shows a scene (built-in name, scene file or mesh, or a :class:`Scene` built in
    Python) in the browser while it renders, as ``canopy view`` does, and returns the
    running :class:`Viewer`: open ``viewer.url`` (in a notebook the viewer shows the page
    inline), and ``viewer.stop()`` when done (or use it in a ``with`` block).

    The page moves the camera, changes settings, rebuilds the tree with another builder,
    width or leaf size, shows the traversal-cost heat map and the tree's boxes, walks a
    clicked pixel's ray through the tree, and saves images into ``output_dir``. It is
    served on ``bind`` (this machine only, a free port, by default) behind a random token
    that ``url`` carries. A scene read from files is loaded again when they change
    (``reload=False``: not). ``size`` is (width, height); the render options start as
    :func:`render` takes them and the page changes them, all but ``size``, ``device``
    and ``threads``. ``device="gpu"`` renders on the first GPU adapter found (see
    :func:`devices`) through binary trees (``width`` 2, the default there) with the
    watertight triangle test; elsewhere ``width`` is 8 unless given. The call returns
    at once: the viewer runs on threads of its own until stopped."""
    options = _render_options(locals())
    native = _canopy.view(
        scene._native.native if isinstance(scene, Scene) else str(scene),
        options,
        bind=str(bind),
        output_dir=str(output_dir),
        allow_paths=[str(p) for p in allow_paths],
        reload=bool(reload),
    )
    return Viewer(native)


def write_image(path, image) -> None:
    """Writes a linear float32 (height, width, 3) image as ``canopy render`` writes its
    output: ``.png`` (8-bit sRGB) or ``.exr`` (linear float, exactly these values),
    atomically: a failed write leaves no file."""
    image = _array(image, "image", np.float32, 3, "(height, width, 3)")
    _canopy.write_image(str(path), image)


def read_image(path) -> np.ndarray:
    """An image file as float32 (height, width, 3): EXR linear values, PNG 8-bit values
    / 255 as stored (sRGB-encoded)."""
    return _canopy.read_image(str(path))
