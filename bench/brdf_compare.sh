#!/usr/bin/env bash
# canopy's glTF metallic-roughness BRDF against Mitsuba 3's (scalar_rgb, from PyPI):
# values and densities at 10,000 direction pairs per model and roughness.
#   bench/brdf_compare.sh [--pairs N] [--write-reference crates/canopy-render/tests/data/mitsuba_ggx.csv]
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/venv.sh numpy "mitsuba==3.*"
exec bench/.venv/bin/python bench/brdf_compare.py "$@"
