# Sourced by the bench scripts: makes bench/.venv if needed, installs the packages given
# as arguments and maturin, and builds canopy's wheel into it (unless CANOPY_BENCH_WHEEL=0).
# Run from the repository root.
if [ ! -x bench/.venv/bin/python ]; then
  python3 -m venv bench/.venv
fi
bench/.venv/bin/pip install --quiet --disable-pip-version-check "$@" "maturin>=1.9,<2"
# Scripts that do not call canopy from Python (kernel_profile.sh) set CANOPY_BENCH_WHEEL=0:
# the wheel is a release build of several minutes.
if [ "${CANOPY_BENCH_WHEEL:-1}" != 0 ]; then
  rm -rf target/bench-wheels
  bench/.venv/bin/maturin build --release --quiet -m crates/canopy-py/Cargo.toml -o target/bench-wheels
  bench/.venv/bin/pip install --quiet --disable-pip-version-check --force-reinstall --no-deps target/bench-wheels/canopy_rt-*.whl
fi
