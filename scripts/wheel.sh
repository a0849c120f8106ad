#!/usr/bin/env bash
# Builds canopy's Python wheel (distribution canopy-rt, import canopy_rt) into
# target/wheels: one abi3 wheel for every CPython >= 3.9 on this platform, which
# `pip install target/wheels/canopy_rt-*.whl` installs in seconds. Needs Python 3.9+
# with venv and the Rust toolchain; maturin is installed into target/py-venv.
#
# Usage: scripts/wheel.sh [PROFILE]. PROFILE is a Cargo profile, `release` (the default:
# the wheel users install) or `test-opt` (what scripts/test.sh tests: it shares the Rust
# tests' compiled crates, so the wheel costs canopy-py and pyo3's crates, not a second build).
set -euo pipefail
cd "$(dirname "$0")/.."
profile=${1:-release}
venv=target/py-venv
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check "maturin>=1.9,<2"
rm -rf target/wheels
"$venv/bin/maturin" build --profile "$profile" --quiet -m crates/canopy-py/Cargo.toml -o target/wheels
ls target/wheels/canopy_rt-*.whl
