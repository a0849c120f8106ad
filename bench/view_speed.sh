#!/usr/bin/env bash
# How quickly `canopy view` answers, as a page sees it through a real socket: the first
# frame after start, the preview and the first full-size frame after a camera move,
# frames per second while the camera moves every 16 ms, the time to 64 spp. Arguments are
# passed on (default: paper-1, cornell and the glTF milk truck at 640x480), e.g.
#   bench/view_speed.sh --size 480x270 --threads 2 [--device gpu]
set -euo pipefail
cd "$(dirname "$0")/.."
exec cargo run --quiet --release -p canopy-view --example view_speed -- "$@"
