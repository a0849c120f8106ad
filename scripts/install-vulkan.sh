#!/usr/bin/env bash
# Installs Mesa's software Vulkan driver (lavapipe) and the Vulkan loader from Debian's
# packages when they are missing, so that canopy's GPU tests run on a machine without a
# GPU. Needs root or sudo without a password (it never asks for one: the test script runs it
# unattended); does nothing when both are present.
set -euo pipefail
PATH="$PATH:/usr/sbin:/sbin"  # ldconfig, for users whose PATH lacks them
if ldconfig -p | grep -q 'libvulkan.so.1' && ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1; then
    exit 0
fi
sudo=""
if [ "$(id -u)" != 0 ]; then
    if ! sudo -n true 2>/dev/null; then
        echo "installing Mesa's software Vulkan driver needs root: run as root, or: sudo apt-get install mesa-vulkan-drivers libvulkan1" >&2
        exit 1
    fi
    sudo="sudo -n"
fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq mesa-vulkan-drivers libvulkan1 >/dev/null
