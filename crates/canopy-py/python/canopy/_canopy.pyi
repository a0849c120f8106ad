# Type stubs of the native module; the documented API is in __init__.py.
from __future__ import annotations

from typing import Callable, Optional, Tuple

import numpy as np

__version__: str

def builders() -> list[str]: ...
def load_scene(scene: str) -> SceneInfo: ...
def load_mesh(path: str) -> Tuple[np.ndarray, np.ndarray]: ...
def read_image(path: str) -> np.ndarray: ...
def render(
    scene: str,
    spp: Optional[int] = ...,
    size: Optional[Tuple[int, int]] = ...,
    seed: Optional[int] = ...,
    max_depth: Optional[int] = ...,
    integrator: Optional[str] = ...,
    russian_roulette: Optional[bool] = ...,
    device: str = ...,
    bvh: str = ...,
    width: int = ...,
    threads: Optional[int] = ...,
    progress: Optional[Callable[[int, int], None]] = ...,
) -> np.ndarray: ...

class SceneInfo:
    @property
    def name(self) -> str: ...
    @property
    def description(self) -> str: ...
    @property
    def settings(self) -> dict: ...
    @property
    def counts(self) -> dict: ...
    @property
    def bounds(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]: ...
    @property
    def warnings(self) -> list[str]: ...

class Bvh:
    def __init__(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        builder: str = ...,
        width: int = ...,
        max_leaf_size: Optional[int] = ...,
        sah_traversal: Optional[float] = ...,
        sah_intersection: Optional[float] = ...,
        ploc_radius: Optional[int] = ...,
        max_duplication: Optional[float] = ...,
        optimize: Optional[float] = ...,
        threads: Optional[int] = ...,
    ) -> None: ...
    @staticmethod
    def from_boxes(
        boxes: np.ndarray,
        builder: str = ...,
        width: int = ...,
        max_leaf_size: Optional[int] = ...,
        sah_traversal: Optional[float] = ...,
        sah_intersection: Optional[float] = ...,
        ploc_radius: Optional[int] = ...,
        max_duplication: Optional[float] = ...,
        optimize: Optional[float] = ...,
        threads: Optional[int] = ...,
    ) -> Bvh: ...
    @property
    def primitive_count(self) -> int: ...
    @property
    def builder(self) -> str: ...
    @property
    def width(self) -> int: ...
    def stats(self) -> dict: ...
    def validate(self) -> None: ...
    def epo(self) -> float: ...
    def intersect(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        tnear: float | np.ndarray,
        tfar: float | np.ndarray,
        threads: Optional[int] = ...,
    ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]: ...
    def occluded(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        tnear: float | np.ndarray,
        tfar: float | np.ndarray,
        threads: Optional[int] = ...,
    ) -> np.ndarray: ...
