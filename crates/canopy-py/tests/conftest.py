import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
MESHES = ROOT / "scenes" / "meshes"
GLTF = ROOT / "scenes" / "gltf"


@pytest.fixture(scope="session")
def canopy_bin() -> Path:
    """The `canopy` binary of the same checkout: $CANOPY_BIN (the test script sets it), else
    the test profile's build, else the release build."""
    built = [ROOT / "target" / profile / "canopy" for profile in ("test-opt", "release")]
    default = next((p for p in built if p.exists()), built[0])
    path = Path(os.environ.get("CANOPY_BIN", default))
    assert path.exists(), f"{path} is missing: run the tests through scripts/test.sh"
    return path


def random_soup(n: int, seed: int):
    """n random triangles in the unit cube, as vertices and faces."""
    rng = np.random.default_rng(seed)
    centres = rng.random((n, 1, 3))
    vertices = (centres + 0.15 * (rng.random((n, 3, 3)) - 0.5)).reshape(-1, 3).astype(np.float32)
    return vertices, np.arange(3 * n).reshape(n, 3)


def edge_midpoint_rays(vertices, faces, seed: int):
    """A ray from a random point around the unit cube to the midpoint of each triangle's
    first edge, as (origins, directions) with the midpoint at t = 1: where the watertight
    and fast triangle tests can differ."""
    rng = np.random.default_rng(seed)
    triangles = vertices[faces]
    targets = 0.5 * (triangles[:, 0] + triangles[:, 1])
    origins = (rng.random((len(targets), 3), dtype=np.float32) * 8 - 4).astype(np.float32)
    return origins, targets - origins


def random_rays(n: int, seed: int):
    """Rays from around the unit cube towards random points inside it."""
    rng = np.random.default_rng(seed)
    origins = rng.random((n, 3)) * 3 - 1
    targets = rng.random((n, 3))
    return origins.astype(np.float32), (targets - origins).astype(np.float32)
