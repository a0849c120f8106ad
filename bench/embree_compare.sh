#!/usr/bin/env bash
# canopy against Embree 4 on the same meshes and rays: makes a venv with embreex and numpy
# (bench/.venv), builds canopy's ray tracer, runs bench/embree_compare.py. Arguments are
# passed on (e.g. --meshes a.ply b.ply --runs 3 --size 512).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x bench/.venv/bin/python ]; then
  python3 -m venv bench/.venv
  bench/.venv/bin/pip install --quiet embreex numpy
fi
cargo build --release --quiet -p canopy-render --example trace_rays
exec bench/.venv/bin/python bench/embree_compare.py --trace target/release/examples/trace_rays "$@"
