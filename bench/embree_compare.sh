#!/usr/bin/env bash
# canopy against Embree 4 on the same meshes and rays, both through Python: makes a venv
# with embreex and numpy (bench/.venv), builds canopy's wheel into it, runs
# bench/embree_compare.py. Arguments are passed on (e.g. --meshes a.ply b.ply --runs 3).
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/venv.sh embreex numpy
# Build times on one core and on two (Embree sizes its thread pool by the CPU affinity).
taskset -c 0 bench/.venv/bin/python bench/embree_compare.py --build-only "$@"
taskset -c 0,1 bench/.venv/bin/python bench/embree_compare.py --build-only "$@"
exec bench/.venv/bin/python bench/embree_compare.py "$@"
