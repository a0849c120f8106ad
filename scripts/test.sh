#!/usr/bin/env bash
# The test command: Rust tests, then the Python bindings built into a venv of their own
# (target/py-venv) and tested with pytest, then trimesh's own ray tests run against
# canopy's engine. Needs Python 3.9+ with venv; installs maturin, numpy, pytest, trimesh
# (pinned: its tests are) with what its tests use, matplotlib, ray (a local Ray instance
# for the distributed tests) and playwright (it drives Debian's Chromium, installed by
# scripts/install-chromium.sh, in the viewer's browser test) into the venv from PyPI,
# while the Rust tests build.
#
# Everything is built once, in the `test-opt` profile (Cargo.toml): the Rust tests, the
# `canopy` binary the Python tests drive, and the wheel, which reuses the tests' crates.
# The GPU tests need a Vulkan adapter: Mesa's software driver is installed when it is
# missing and this user may install packages; otherwise they skip, and the summary says so.
# Open Image Denoise is installed into target/oidn (scripts/oidn.sh) for the denoising tests.
set -euo pipefail
cd "$(dirname "$0")/.."
profile=test-opt
venv=target/py-venv
mkdir -p target

scripts/install-vulkan.sh >target/install-vulkan.log 2>&1 ||
    echo "note: could not install Mesa's software Vulkan driver (target/install-vulkan.log)"
# Chromium for the viewer's browser test, installed while the Rust tests build.
scripts/install-chromium.sh >target/install-chromium.log 2>&1 &
chromium_pid=$!

# The denoiser's library (from PyPI's pyoidn wheel), so that the denoising tests run the
# real one: they fail, rather than skip, when it is missing.
scripts/oidn.sh target/oidn >target/oidn.log 2>&1 || {
    cat target/oidn.log
    echo "error: could not install Open Image Denoise (scripts/oidn.sh)" >&2
    exit 1
}
export CANOPY_OIDN="$PWD/target/oidn" CANOPY_REQUIRE_OIDN=1

# The Python packages download while the Rust tests compile and run.
python_env() {
    if [ ! -x "$venv/bin/python" ]; then
        python3 -m venv "$venv"
    fi
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
        "maturin>=1.9,<2" numpy pytest "trimesh==5.2.0" rtree scipy shapely networkx manifold3d embreex ray \
        matplotlib playwright
}
python_env >target/py-venv.log 2>&1 &
python_env_pid=$!

# The tests (unit, integration, then documentation), not the examples: they are measuring
# programs, which `cargo test` would compile (an eighth of the build); clippy checks them.
# Both runs select the whole workspace: a smaller selection resolves other features and
# would build everything again.
status=0
cargo test --workspace --profile "$profile" --no-fail-fast --tests || status=1
cargo test --workspace --profile "$profile" --no-fail-fast --doc || status=1

canopy_bin="$PWD/target/$profile/canopy"
gpu_note=""
if ! "$canopy_bin" devices >/dev/null 2>&1; then
    gpu_note="GPU tests SKIPPED: no GPU adapter. Install a Vulkan driver (as root: scripts/install-vulkan.sh installs Mesa's software one) and run scripts/test.sh again."
fi

if ! wait "$python_env_pid"; then
    cat target/py-venv.log
    echo "error: could not install the Python test packages into $venv" >&2
    exit 1
fi
scripts/wheel.sh "$profile"
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps target/wheels/canopy_rt-*.whl
# Every suite runs, whatever the one before says.
CANOPY_BIN="$canopy_bin" "$venv/bin/python" -m pytest -q crates/canopy-py/tests || status=1
(cd crates/canopy-py/trimesh-suite &&
    "../../../$venv/bin/python" -m pytest -q -p no:cacheprovider tests/test_ray.py tests/test_ray_upstream.py) || status=1

# The viewer in a real browser: `canopy view` driven through headless Chromium.
browser_note=""
if wait "$chromium_pid" && command -v chromium >/dev/null 2>&1; then
    CANOPY_BIN="$canopy_bin" CANOPY_TEST_OUT=target/view-browser \
        "$venv/bin/python" -m pytest -q crates/canopy-view/tests/browser || status=1
else
    browser_note="browser test SKIPPED: no Chromium (target/install-chromium.log). As root, scripts/install-chromium.sh installs Debian's."
fi

if [ -n "$browser_note" ]; then
    echo "$browser_note"
fi
if [ -n "$gpu_note" ]; then
    echo "$gpu_note"
fi
exit $status
