#!/usr/bin/env bash
# System libraries MuJoCo needs to render offscreen (EGL and OSMesa). Installs only what is
# missing, and only where apt-get is available and we are root; otherwise says what to install.
set -euo pipefail
packages=(libegl1 libosmesa6)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if command -v apt-get >/dev/null && [ "$(id -u)" -eq 0 ]; then
  echo "installing system packages: ${missing[*]}"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
else
  echo "warning: offscreen rendering needs: ${missing[*]} (install them with your package manager)" >&2
fi
