#!/usr/bin/env bash
# canopy's point queries against Open3D's RaycastingScene: makes bench/.venv (open3d,
# numpy), builds canopy's wheel into it and runs bench/distance_compare.py. Open3D needs
# Debian's libusb-1.0-0 (`apt-get install libusb-1.0-0`). Arguments are passed on (e.g.
# --mesh a.ply --points 100000 --runs 5).
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/venv.sh open3d numpy
exec bench/.venv/bin/python bench/distance_compare.py "$@"
