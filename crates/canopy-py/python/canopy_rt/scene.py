"""Scenes built from Python: meshes from numpy arrays placed by instances, spheres,
boxes, materials, a camera, a background and render settings, rendered by
``canopy.render(scene)`` exactly as a scene file with the same contents would be.

>>> import numpy as np, canopy_rt as canopy
>>> scene = canopy.Scene(size=(64, 48), spp=4)
>>> scene.camera(look_from=(0, 1, 4), look_at=(0, 0, 0))
>>> quad = scene.add_mesh([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]],
...                       [[0, 2, 1], [0, 3, 2]], material=canopy.lambertian((0.7, 0.7, 0.7)))
>>> scene.add_sphere((0, 0.5, 0), 0.5, material=canopy.metal((0.9, 0.8, 0.6), fuzz=0.1))
>>> image = canopy.render(scene)

Every call is checked as the scene file parser checks its entries; a refused call
raises ``ValueError`` naming the argument and leaves the scene as it was.

A scene pickles (for multiprocessing, Ray tasks and ``canopy_rt.distributed``): it is
rebuilt by repeating its calls, which read the files they name (glTF models,
environment maps) again where it is unpickled.
"""

from __future__ import annotations

import os
from typing import Callable, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _canopy
from ._arguments import naming_arguments_of_methods

Material = Union[dict, int]
"""A material: a dict as a scene file writes it (see :func:`lambertian` and friends), or
the index :meth:`Scene.add_material` returned."""


def lambertian(albedo) -> dict:
    """An ideal diffuse surface; ``albedo`` is (r, g, b), each in [0, 1]."""
    return {"type": "lambertian", "albedo": [float(c) for c in albedo]}


def metal(albedo, fuzz: float = 0.0) -> dict:
    """A mirror tinted by ``albedo``, blurred by ``fuzz`` in [0, 1] (0 is a perfect mirror)."""
    return {"type": "metal", "albedo": [float(c) for c in albedo], "fuzz": float(fuzz)}


def dielectric(ior: float) -> dict:
    """Glass-like refraction with index of refraction ``ior`` (1.5 for glass)."""
    return {"type": "dielectric", "ior": float(ior)}


def emissive(radiance) -> dict:
    """A light: emits ``radiance`` (r, g, b), each >= 0, from both sides."""
    return {"type": "emissive", "radiance": [float(c) for c in radiance]}


def pbr(base_color, metallic: float = 0.0, roughness: float = 1.0, emission=None) -> dict:
    """glTF's metallic-roughness material: GGX over a diffuse base. ``base_color`` is
    (r, g, b) in [0, 1] (linear), ``metallic`` 0 for a dielectric and 1 for a metal,
    ``roughness`` from 0 (polished) to 1; with ``emission`` (an (r, g, b) radiance) the
    surface also glows, from both sides, and is a light."""
    material = {
        "type": "pbr",
        "base_color": [float(c) for c in base_color],
        "metallic": float(metallic),
        "roughness": float(roughness),
    }
    if emission is not None:
        material["emission"] = [float(c) for c in emission]
    return material


def eval_material(material: dict, wo, wi):
    """The BSDF of ``material`` times the cosine, and the density with which the renderer
    samples it, for direction pairs: ``wo`` towards the viewer and ``wi`` towards the light,
    (n, 3) arrays of unit vectors in the surface's frame (its normal is +z). Returns a
    float32 array (n, 3) of values and one (n,) of densities per steradian."""
    wo = np.ascontiguousarray(wo, dtype=np.float32).reshape(-1, 3)
    wi = np.ascontiguousarray(wi, dtype=np.float32).reshape(-1, 3)
    return _canopy.eval_material(material, wo, wi)


def _transform(transform) -> np.ndarray:
    """A (3, 4) float32 affine matrix from a 4x4 or 3x4 matrix (column vectors), or the
    identity for None."""
    if transform is None:
        return np.eye(4, dtype=np.float32)[:3]
    m = np.asarray(transform, dtype=np.float64)
    if m.shape == (4, 4):
        if not np.array_equal(m[3], [0, 0, 0, 1]):
            raise ValueError(f"transform: the last row of a 4x4 affine matrix must be [0, 0, 0, 1], not {m[3].tolist()}")
        m = m[:3]
    if m.shape != (3, 4):
        raise ValueError(f"transform must be a 4x4 or 3x4 matrix, not shape {m.shape}")
    return np.ascontiguousarray(m, dtype=np.float32)


def _vec3(value, name: str) -> Tuple[float, float, float]:
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    if v.shape != (3,):
        raise ValueError(f"{name} must be three numbers, not {value!r}")
    return (float(v[0]), float(v[1]), float(v[2]))


# The arguments of these native calls that name files or folders (a path, or a list of
# them), by position.
_FILE_ARGUMENTS = {"set_environment": (0,), "add_gltf": (0, 2)}


def _paths(value, change: Callable[[str], str]):
    """``change`` applied to a path, or to each path of a list."""
    if isinstance(value, (list, tuple)):
        return [change(os.fspath(v)) for v in value]
    return change(os.fspath(value))


class _Recorder:
    """The native scene, with a record of the calls that succeeded on it: enough to
    build the same scene again elsewhere (files named by absolute paths)."""

    def __init__(self, name: str):
        self.name = name
        self.native = _canopy.Scene(name)
        self.calls: List[Tuple[str, tuple]] = []

    def __getattr__(self, method: str):
        native_method = getattr(self.native, method)

        def call(*args):
            if method in _FILE_ARGUMENTS:
                args = list(args)
                for i in _FILE_ARGUMENTS[method]:
                    args[i] = _paths(args[i], os.path.abspath)
                args = tuple(args)
            result = native_method(*args)
            if method.startswith(("set_", "add_")):
                self.calls.append((method, args))
            return result

        return call

    @classmethod
    def replay(cls, name: str, calls, where: Callable[[str], str] = lambda path: path) -> "_Recorder":
        """The scene these calls build, each file looked for at ``where(path)``."""
        recorder = cls(name)
        for method, args in calls:
            if method in _FILE_ARGUMENTS:
                args = list(args)
                for i in _FILE_ARGUMENTS[method]:
                    args[i] = _paths(args[i], where)
            getattr(recorder, method)(*args)
        return recorder


@naming_arguments_of_methods
class Scene:
    """A scene under construction. ``size`` is (width, height); the other settings are
    those of a scene file's ``[render]`` table."""

    def __init__(
        self,
        *,
        size: Tuple[int, int] = (640, 480),
        spp: int = 64,
        max_depth: int = 8,
        seed: int = 0,
        integrator: str = "path",
        russian_roulette: bool = True,
        sampler: str = "sobol",
        name: str = "",
    ):
        self._native = _Recorder(str(name))
        self._mesh_materials = {}
        self.settings(
            size=size,
            spp=spp,
            max_depth=max_depth,
            seed=seed,
            integrator=integrator,
            russian_roulette=russian_roulette,
            sampler=sampler,
        )

    def settings(
        self,
        *,
        size: Tuple[int, int],
        spp: int,
        max_depth: int = 8,
        seed: int = 0,
        integrator: str = "path",
        russian_roulette: bool = True,
        sampler: str = "sobol",
    ) -> None:
        """Sets every render setting (``canopy.render`` may still override them)."""
        width, height = (int(size[0]), int(size[1]))
        self._native.set_settings(
            width, height, int(spp), int(max_depth), int(seed), str(integrator), bool(russian_roulette),
            str(sampler),
        )

    def camera(
        self,
        look_from,
        look_at,
        *,
        up=(0.0, 1.0, 0.0),
        vfov: float = 40.0,
        aperture: float = 0.0,
        focus_distance: Optional[float] = None,
        ortho_height: Optional[float] = None,
    ) -> None:
        """Places the camera: ``vfov`` is the vertical field of view in degrees;
        ``aperture`` > 0 blurs what is not at ``focus_distance`` (default: ``look_at``).
        With ``ortho_height`` the camera is orthographic: parallel rays from a view that
        high (in world units; its width follows the image's aspect)."""
        self._native.set_camera(
            _vec3(look_from, "look_from"),
            _vec3(look_at, "look_at"),
            _vec3(up, "up"),
            float(vfov),
            float(aperture),
            None if focus_distance is None else float(focus_distance),
            None if ortho_height is None else float(ortho_height),
        )

    def background(self, value="sky", *, environment=None, rotate=0.0, strength: float = 1.0) -> None:
        """The light from where no surface is: ``"sky"`` (the report's gradient), an
        (r, g, b) radiance, or ``environment="file.hdr"`` (or .exr), turned by ``rotate``
        degrees about the vertical (or (x, y, z) Euler degrees) and scaled by
        ``strength``."""
        if environment is not None:
            angles = (0.0, float(rotate), 0.0) if np.isscalar(rotate) else _vec3(rotate, "rotate")
            self._native.set_environment(str(environment), angles, float(strength))
        elif isinstance(value, str):
            if value != "sky":
                raise ValueError(f'background must be "sky", an (r, g, b) radiance or environment=..., not {value!r}')
            self._native.set_sky()
        else:
            self._native.set_background_color(_vec3(value, "background"))

    def add_material(self, material: dict) -> int:
        """Adds a material (a dict from :func:`lambertian` and friends); returns its index,
        which every ``material=`` argument also takes."""
        if not isinstance(material, dict):
            raise TypeError(f"a material is a dict such as canopy_rt.lambertian((0.5, 0.5, 0.5)), not {type(material).__name__}")
        return self._native.add_material(material)

    @staticmethod
    def _material(material: Material):
        """An index, or a dict that the native call adds only if it succeeds."""
        if isinstance(material, (int, np.integer)) and not isinstance(material, bool):
            return int(material)
        if not isinstance(material, dict):
            raise TypeError(f"a material is a dict such as canopy_rt.lambertian((0.5, 0.5, 0.5)) or an index, not {type(material).__name__}")
        return material

    def add_point_light(self, position, intensity) -> None:
        """Adds a point light of ``intensity`` (r, g, b): a surface facing it at distance d
        receives irradiance intensity / d² (a white sky gives an open floor π)."""
        self._native.add_point_light(_vec3(position, "position"), _vec3(intensity, "intensity"))

    def add_spot_light(self, position, direction, intensity, *, inner_angle: float = 0.0,
                       outer_angle: float = 45.0) -> None:
        """Adds a spot light shining along ``direction``: full ``intensity`` within
        ``inner_angle`` degrees of it, fading to nothing at ``outer_angle``."""
        self._native.add_point_light(
            _vec3(position, "position"), _vec3(intensity, "intensity"),
            (_vec3(direction, "direction"), float(inner_angle), float(outer_angle)),
        )

    def add_directional_light(self, direction, irradiance) -> None:
        """Adds light from infinitely far away travelling along ``direction``, bringing
        ``irradiance`` (r, g, b) to a surface facing it."""
        self._native.add_directional_light(_vec3(direction, "direction"), _vec3(irradiance, "irradiance"))

    def add_sphere(self, center, radius: float, *, material: Material) -> None:
        self._native.add_sphere(_vec3(center, "center"), float(radius), self._material(material))

    def add_spheres(self, centers, radii, *, material: Material) -> None:
        """Adds spheres at the rows of ``centers`` (n, 3) with ``radii`` (n,) or one radius."""
        centers = np.ascontiguousarray(np.asarray(centers, dtype=np.float32).reshape(-1, 3))
        radii = np.asarray(radii, dtype=np.float32)
        if radii.ndim == 0:
            radii = np.full(len(centers), radii, dtype=np.float32)
        self._native.add_spheres(centers, np.ascontiguousarray(radii.reshape(-1)), self._material(material))

    def add_box(self, min, max, *, material: Material, rotate=(0.0, 0.0, 0.0), translate=(0.0, 0.0, 0.0)) -> None:
        """Adds the box ``min``..``max``, rotated by (x, y, z) Euler degrees, then translated."""
        self._native.add_box(
            _vec3(min, "min"), _vec3(max, "max"), _vec3(rotate, "rotate"), _vec3(translate, "translate"),
            self._material(material),
        )

    def add_mesh(
        self,
        vertices,
        faces,
        *,
        material: Material = None,
        transform=None,
        normals=None,
        smooth: bool = False,
        name: str = "",
    ) -> int:
        """Adds a triangle mesh, stored once, and places one instance of it by
        ``transform`` (4x4 or 3x4, column vectors; identity by default) with
        ``material`` (grey by default). Returns the mesh's index for :meth:`add_instance`.
        ``normals`` (one per vertex) or ``smooth=True`` (computed) shade it smoothly."""
        vertices = np.ascontiguousarray(np.asarray(vertices, dtype=np.float32))
        faces = np.ascontiguousarray(np.asarray(faces, dtype=np.int64))
        if vertices.ndim != 2 or faces.ndim != 2:
            raise ValueError("vertices must have shape (n, 3) and faces (m, 3)")
        if normals is not None:
            normals = np.ascontiguousarray(np.asarray(normals, dtype=np.float32))
            if normals.ndim != 2:
                raise ValueError("normals must have shape (n, 3)")
        material = self._material(lambertian((0.7, 0.7, 0.7)) if material is None else material)
        mesh, material = self._native.add_mesh(
            str(name), vertices, faces, normals, bool(smooth), _transform(transform), material
        )
        self._mesh_materials[mesh] = material
        return mesh

    def add_instance(self, mesh: int, transform=None, *, material: Material = None) -> int:
        """Places another copy of mesh ``mesh`` by ``transform`` (any invertible affine
        matrix: rotations, mirrors, non-uniform scale), with ``material`` or the one
        the mesh was added with. Returns the instance's index. The mesh is not copied."""
        if material is None:
            if mesh not in self._mesh_materials:
                raise ValueError(f"add_instance: mesh {mesh} does not exist")
            material = self._mesh_materials[mesh]
        return self._native.add_instance(int(mesh), _transform(transform), self._material(material))

    def add_gltf(self, path, transform=None, *, allow_paths: Sequence = ()) -> int:
        """Adds the glTF 2.0 model at ``path`` (``.glb``, or ``.gltf`` with its buffers
        beside it), placed by ``transform`` (any invertible affine matrix; identity by
        default): its meshes, materials and node hierarchy, each mesh stored once.
        Returns how many instances it placed. What the model uses that canopy does not
        render yet (textures, alpha modes, punctual lights) is listed in
        ``info().warnings``. The scene's camera is kept. A refused file changes nothing.

        The model's buffers and images are read from its own folder only: a file it
        names elsewhere (``../``, an absolute path, a link out) is refused unless it lies
        in one of the folders ``allow_paths``."""
        return self._native.add_gltf(str(path), _transform(transform), [str(p) for p in allow_paths])

    def info(self) -> "_canopy.SceneInfo":
        """The scene described: ``settings``, ``counts``, ``bounds``, ``warnings``."""
        return self._native.info()

    def __getstate__(self) -> dict:
        return {"name": self._native.name, "calls": list(self._native.calls),
                "mesh_materials": dict(self._mesh_materials)}

    def __setstate__(self, state: dict) -> None:
        self._native = _Recorder.replay(state["name"], state["calls"])
        self._mesh_materials = dict(state["mesh_materials"])

    @classmethod
    def _rebuilt(cls, state: dict, where: Callable[[str], str]) -> "Scene":
        """The pickled scene ``state``, each file it reads looked for at ``where(path)``."""
        scene = cls.__new__(cls)
        scene._native = _Recorder.replay(state["name"], state["calls"], where)
        scene._mesh_materials = dict(state["mesh_materials"])
        return scene

    def __repr__(self) -> str:
        return repr(self._native.native)
