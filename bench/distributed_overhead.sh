#!/usr/bin/env bash
# canopy_rt.distributed's overhead per task, cost per MB shipped and speedup on 1 and 2
# local Ray nodes, and a model of 8, 64 and 512 nodes: bench/distributed_overhead.py.
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/venv.sh numpy "ray==2.60.0"
exec bench/.venv/bin/python bench/distributed_overhead.py "$@"
