#!/usr/bin/env bash
# Where a ray's time goes in canopy's and Embree's single-ray kernels, on the same rays:
# ns per ray (native), instructions, cache misses and mispredicted branches per ray
# (valgrind's callgrind), canopy's node visits and primitive tests. Needs valgrind and a C
# compiler. Arguments are passed on (e.g. --meshes a.ply --incoherent 50000 --no-valgrind).
set -euo pipefail
cd "$(dirname "$0")/.."
CANOPY_BENCH_WHEEL=0 source bench/venv.sh embreex numpy
cargo build --release --quiet -p canopy-render --example kernel_profile
exec bench/.venv/bin/python bench/kernel_profile.py "$@"
