#!/usr/bin/env bash
# Installs Intel Open Image Denoise 2 (its library and CPU device, with the TBB they
# need) where canopy finds it, for `canopy render --denoise` and canopy_rt.denoise. The
# libraries come from PyPI's pyoidn wheel (pinned by version and hash), which ships
# OIDN's official Linux x86-64 build; nothing is compiled.
#
#   scripts/oidn.sh [DIR]   installs into DIR/lib [default: ~/.local/share/canopy/oidn,
#                           the folder canopy looks in; elsewhere, set CANOPY_OIDN=DIR]
#
# Does nothing when DIR/lib already holds this version.
set -euo pipefail
version=2.5.1.0
sha256=32ad13368f8de1ef63001942ad05b02a00cd732d1206d97f352d3a3f606d823e
wheel="pyoidn-$version-py3-none-manylinux2014_x86_64.whl"
dest="${1:-${XDG_DATA_HOME:-$HOME/.local/share}/canopy/oidn}"
lib="$dest/lib"

if [ "$(uname -s)-$(uname -m)" != "Linux-x86_64" ]; then
    echo "scripts/oidn.sh installs OIDN for Linux x86-64; elsewhere get it from https://www.openimagedenoise.org and set CANOPY_OIDN to its folder" >&2
    exit 1
fi
if [ -f "$lib/.pyoidn-$version" ]; then
    exit 0
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
# pip only downloads the wheel; a Python without pip gets one in a throwaway venv.
pip=(python3 -m pip)
if ! python3 -m pip --version >/dev/null 2>&1; then
    python3 -m venv "$work/venv"
    pip=("$work/venv/bin/python" -m pip)
fi
"${pip[@]}" download --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
    --platform manylinux2014_x86_64 --python-version 3.11 --dest "$work" "pyoidn==$version"
echo "$sha256  $work/$wheel" | sha256sum --check --quiet
mkdir -p "$lib"
# The CPU device and what it loads; the GPU devices (another 17 MB) are left out.
python3 - "$work/$wheel" "$lib" <<'PY'
import os, shutil, sys, zipfile
wheel, lib = sys.argv[1:]
wanted = ["libOpenImageDenoise.so.2", "libOpenImageDenoise_core.so.2.5.1",
          "libOpenImageDenoise_device_cpu.so.2.5.1", "libtbb.so.12"]
with zipfile.ZipFile(wheel) as z:
    for name in wanted:
        with z.open("pyoidn/oidn/lib/" + name) as src, open(os.path.join(lib, name + ".part"), "wb") as out:
            shutil.copyfileobj(src, out)
        os.chmod(os.path.join(lib, name + ".part"), 0o755)
        os.replace(os.path.join(lib, name + ".part"), os.path.join(lib, name))
PY
touch "$lib/.pyoidn-$version"
echo "Open Image Denoise $version installed in $lib"
