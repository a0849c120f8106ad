#!/usr/bin/env bash
# How well SAH and EPO predict ray cost across builders: makes bench/.venv (numpy,
# matplotlib), builds canopy's wheel into it and runs bench/sah_epo.py. Arguments are
# passed on (e.g. --meshes a.ply b.ply --plot out.png).
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/venv.sh numpy matplotlib
exec bench/.venv/bin/python bench/sah_epo.py "$@"
