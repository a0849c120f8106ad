#!/usr/bin/env bash
# Installs Debian's Chromium when it is missing, for the viewer's browser test
# (crates/canopy-view/tests/browser, driven by Playwright for Python). Needs root or sudo
# without a password (it never asks for one: the test script runs it unattended); does
# nothing when Chromium is there.
set -euo pipefail
if command -v chromium >/dev/null 2>&1; then
    exit 0
fi
sudo=""
if [ "$(id -u)" != 0 ]; then
    if ! sudo -n true 2>/dev/null; then
        echo "installing Chromium needs root: run as root, or: sudo apt-get install chromium" >&2
        exit 1
    fi
    sudo="sudo -n"
fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq chromium >/dev/null
