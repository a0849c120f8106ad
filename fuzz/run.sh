#!/usr/bin/env bash
# Fuzzes one target for a while: fuzz/run.sh TARGET [SECONDS] (default 600).
# Needs a nightly toolchain and cargo-fuzz (`rustup toolchain install nightly`,
# `cargo install cargo-fuzz`). The corpus grows in fuzz/corpus/TARGET (not committed),
# starting from the committed seeds in fuzz/seeds/TARGET.
set -euo pipefail
cd "$(dirname "$0")"
target=${1:?"usage: fuzz/run.sh TARGET [SECONDS]; targets: $(ls fuzz_targets | sed 's/\.rs$//' | tr '\n' ' ')"}
seconds=${2:-600}
[ -f "fuzz_targets/$target.rs" ] || { echo "no fuzz target $target" >&2; exit 2; }
mkdir -p "corpus/$target"
exec cargo +nightly fuzz run -O "$target" "corpus/$target" "seeds/$target" -- \
    -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10
