#!/usr/bin/env bash
# canopy against Mitsuba 3 (llvm_ad_rgb, from PyPI) rendering the same scene in one run:
# speed at equal spp and at equal noise, and whether the images agree.
#   bench/mitsuba_render.sh [paper-1 paper-3 ...] [--spp 64] [--size 480x480] [--depth 5]
#                           [--threads 2] [--turns 3] [--images DIR]
# Mitsuba's LLVM backend needs Debian's libllvm19 (installed here when run as root).
set -euo pipefail
cd "$(dirname "$0")/.."
llvm=/usr/lib/x86_64-linux-gnu/libLLVM-19.so
if [ ! -e "$llvm" ] && [ "$(id -u)" = 0 ]; then
  apt-get install -y -qq libllvm19 >/dev/null
fi
[ -e "$llvm" ] && export DRJIT_LIBLLVM_PATH="$llvm"
source bench/venv.sh numpy "mitsuba==3.*"
exec bench/.venv/bin/python bench/mitsuba_render.py "$@"
