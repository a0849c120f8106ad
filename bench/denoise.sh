#!/usr/bin/env bash
# Denoising at equal time (bench/denoise.py): noisy and denoised errors against a 16k-spp
# reference for cornell, paper-3 and a glTF model at 4, 16 and 64 spp, and the
# denoiser's time per megapixel.
#   bench/denoise.sh [--size 128x128] [--reference-spp 16384] [--spp 4,16,64] [--runs 3]
# The references are rendered once and kept in target/bench-denoise.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/oidn.sh
source bench/venv.sh numpy flip-evaluator
exec bench/.venv/bin/python bench/denoise.py "$@"
