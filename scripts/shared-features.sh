#!/usr/bin/env bash
# Checks that canopy-py, built alone (as maturin builds the wheel), asks for the same
# features of every dependency as the workspace's test build does. Where they differ, that
# dependency and everything above it would be compiled twice; the fix is a line in
# canopy-py's Cargo.toml (the workspace hack there), which this names.
set -euo pipefail
cd "$(dirname "$0")/.."
features() {
    cargo tree --quiet -f '{p} {f}' --prefix none "$@" |
        sed -e 's/ (\*)$//' -e 's/ (proc-macro)//' | sort -u
}
tests=$(mktemp) wheel=$(mktemp)
trap 'rm -f "$tests" "$wheel"' EXIT
features --workspace >"$tests"
features -p canopy-py -e normal,build >"$wheel"
python3 - "$tests" "$wheel" <<'PY'
import sys

def read(path):
    crates = {}
    for line in open(path):
        parts = [p for p in line.split() if not p.startswith("(")]  # a path, "(*)"
        if len(parts) >= 2:
            crates[(parts[0], parts[1])] = parts[2] if len(parts) > 2 else ""
    return crates

workspace, wheel = read(sys.argv[1]), read(sys.argv[2])
stale = [
    f"{name} {version}: the tests build it with [{workspace[(name, version)]}], the wheel with [{wheel[key]}]"
    for key in sorted(wheel) if key in workspace and workspace[key] != wheel[key]
    for name, version in [key]
]
if stale:
    print("canopy-py's workspace hack (crates/canopy-py/Cargo.toml) is stale; the wheel would",
          "compile these and all above them again:", *stale, sep="\n  ", file=sys.stderr)
    sys.exit(1)
PY
