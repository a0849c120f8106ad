#!/usr/bin/env bash
# Installs Mesa's software Vulkan driver (lavapipe) and the Vulkan loader from Debian's
# packages when they are missing, so that canopy's GPU tests run on a machine without a
# GPU. Needs root or sudo without a password (scripts/apt-install.sh); does nothing when both
# are present.
set -euo pipefail
PATH="$PATH:/usr/sbin:/sbin"  # ldconfig, for users whose PATH lacks them
if ldconfig -p | grep -q 'libvulkan.so.1' && ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1; then
    exit 0
fi
exec "$(dirname "$0")/apt-install.sh" mesa-vulkan-drivers libvulkan1
