"""Builds a BVH over a mesh, traces one camera ray per pixel, and plots the depth image.

    python examples/depth_image.py [mesh.ply|mesh.obj] [out.png]
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # write files; no window needed
import matplotlib.pyplot as plt
import numpy as np

import canopy_rt as canopy

here = Path(__file__).resolve().parent
mesh = sys.argv[1] if len(sys.argv) > 1 else here.parents[2] / "scenes" / "meshes" / "bunny.ply"
out = sys.argv[2] if len(sys.argv) > 2 else "depth.png"

vertices, faces = canopy.load_mesh(mesh)
bvh = canopy.Bvh(vertices, faces, builder="binned-sah")
print(bvh, bvh.stats()["sah_cost"])

# A pinhole camera in front of the mesh, looking at its centre along -z.
lo, hi = vertices.min(axis=0), vertices.max(axis=0)
centre, size = (lo + hi) / 2, float(np.max(hi - lo))
width, height = 320, 240
xs = np.linspace(-1, 1, width) * size * 0.7
ys = np.linspace(1, -1, height) * size * 0.7 * height / width
px, py = np.meshgrid(xs, ys)
eye = centre + np.array([0, 0, 2.5 * size])
targets = np.stack([centre[0] + px, centre[1] + py, np.full_like(px, centre[2])], axis=-1)
directions = (targets - eye).reshape(-1, 3)
origins = np.broadcast_to(eye, directions.shape)

hits = bvh.intersect(origins, directions)
depth = np.where(np.isfinite(hits.t), hits.t, np.nan).reshape(height, width)
print(f"{np.count_nonzero(hits.prim >= 0)} of {len(hits.t)} rays hit the mesh")

plt.imshow(depth, cmap="viridis")
plt.colorbar(label="distance along the ray (in units of its direction)")
plt.title(Path(mesh).name)
plt.axis("off")
plt.savefig(out, dpi=100, bbox_inches="tight")
print(f"wrote {out}")
