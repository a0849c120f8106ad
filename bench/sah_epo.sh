#!/usr/bin/env bash
# How well SAH and EPO predict ray cost across builders: makes bench/.venv (numpy,
# matplotlib), builds canopy's wheel into it and runs bench/sah_epo.py. Arguments are
# passed on (e.g. --meshes a.ply b.ply --plot out.png).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x bench/.venv/bin/python ]; then
  python3 -m venv bench/.venv
fi
bench/.venv/bin/pip install --quiet --disable-pip-version-check numpy matplotlib "maturin>=1.9,<2"
rm -rf target/bench-wheels
bench/.venv/bin/maturin build --release --quiet -m crates/canopy-py/Cargo.toml -o target/bench-wheels
bench/.venv/bin/pip install --quiet --disable-pip-version-check --force-reinstall --no-deps target/bench-wheels/canopy-*.whl
exec bench/.venv/bin/python bench/sah_epo.py "$@"
