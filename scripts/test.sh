#!/usr/bin/env bash
# The test command: Rust tests, then the Python bindings built into a venv of their own
# (target/py-venv) and tested with pytest, then trimesh's own ray tests run against
# canopy's engine. Needs Python 3.9+ with venv; installs maturin, numpy, pytest, trimesh
# (pinned: its tests are) with what its tests use, matplotlib, and ray (a local Ray
# instance for the distributed tests) into the venv from PyPI.
set -euo pipefail
cd "$(dirname "$0")/.."

cargo test --workspace --release --no-fail-fast

venv=target/py-venv
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
    "maturin>=1.9,<2" numpy pytest "trimesh==5.2.0" rtree scipy shapely networkx manifold3d embreex ray \
    matplotlib
scripts/wheel.sh
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps target/wheels/canopy_rt-*.whl
# Both suites run, whatever the first says.
status=0
CANOPY_BIN="$PWD/target/release/canopy" "$venv/bin/python" -m pytest -q crates/canopy-py/tests || status=1
(cd crates/canopy-py/trimesh-suite &&
    "../../../$venv/bin/python" -m pytest -q -p no:cacheprovider tests/test_ray.py tests/test_ray_upstream.py) || status=1
exit $status
