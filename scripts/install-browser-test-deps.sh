#!/usr/bin/env bash
# Installs what the viewer's browser test needs (tests/view_browser.rs): Debian's headless
# Chromium and ChromeDriver. Does nothing if both are there already. .ci/run calls it.
set -euo pipefail
if command -v chromium >/dev/null && command -v chromedriver >/dev/null; then
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO=sudo; fi
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends chromium chromium-driver >/dev/null
command -v chromium && command -v chromedriver
