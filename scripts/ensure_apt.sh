#!/usr/bin/env bash
# Install the Debian packages the stack needs, only if one is missing (idempotent, quiet when done).
#   libusb-1.0-0 : open3d's shared library links it
#   libosmesa6   : MuJoCo's software renderer when EGL is not available
#   libegl1, libgl1-mesa-dri : MuJoCo's headless EGL renderer
#   chromium     : the web UI's browser test (Playwright drives Debian's Chromium; no browser download)
set -euo pipefail
pkgs=(libusb-1.0-0 libosmesa6 libegl1 libgl1-mesa-dri chromium)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "[setup] installing Debian packages: ${missing[*]}"
sudo_=""
[ "$(id -u)" -eq 0 ] || sudo_="sudo"
export DEBIAN_FRONTEND=noninteractive
$sudo_ apt-get update -qq
$sudo_ apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
