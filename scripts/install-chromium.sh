#!/usr/bin/env bash
# Installs Debian's Chromium when it is missing, for the viewer's browser test
# (crates/canopy-view/tests/browser, driven by Playwright for Python). Needs root or sudo
# without a password (scripts/apt-install.sh); does nothing when Chromium is there.
set -euo pipefail
if command -v chromium >/dev/null 2>&1; then
    exit 0
fi
exec "$(dirname "$0")/apt-install.sh" chromium
