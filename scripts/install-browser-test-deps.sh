#!/usr/bin/env bash
# Installs what the viewer's browser test needs (tests/view_browser.rs): Debian's headless
# Chromium and ChromeDriver; and Mesa's llvmpipe through EGL (libgl1-mesa-dri, libegl1 and
# libegl-mesa0), the software GL of `scripts/measure-view-fps.py --gl llvmpipe`.
# With --lavapipe, also Mesa's Vulkan drivers (mesa-vulkan-drivers: lavapipe, for
# `scripts/measure-view-fps.py --gl lavapipe`). Does nothing if all are there already.
# .ci/run calls it.
set -euo pipefail
packages=(chromium chromium-driver libgl1-mesa-dri libegl1 libegl-mesa0)
if [ "${1:-}" = --lavapipe ]; then packages+=(mesa-vulkan-drivers); fi
missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} = 0 ]; then
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO=sudo; fi
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
command -v chromium && command -v chromedriver
