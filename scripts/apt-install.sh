#!/usr/bin/env bash
# Installs Debian packages unattended, for the scripts that install what the tests need
# (install-vulkan.sh, install-chromium.sh): as root, or through sudo without a password.
# It never asks for one (the test script runs it unattended); without either it says
# which command to run and fails.
set -euo pipefail
sudo=""
if [ "$(id -u)" != 0 ]; then
    if ! sudo -n true 2>/dev/null; then
        echo "installing $* needs root: run as root, or: sudo apt-get install $*" >&2
        exit 1
    fi
    sudo="sudo -n"
fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq "$@" >/dev/null
