#!/usr/bin/env bash
# Debian packages the project needs, installed only when missing, and only where apt-get is
# available and we are root; otherwise says what to install.
#   scripts/install_system_deps.sh                            MuJoCo's offscreen rendering (EGL, OSMesa)
#   scripts/install_system_deps.sh chromium chromium-driver   the page tests' headless browser
set -euo pipefail
if [ $# -gt 0 ]; then packages=("$@"); else packages=(libegl1 libosmesa6); fi
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if command -v apt-get >/dev/null && [ "$(id -u)" -eq 0 ]; then
  echo "installing system packages: ${missing[*]}"
  if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null; }; then
    echo "warning: could not install ${missing[*]} with apt-get; what needs them is skipped or fails with a message" >&2
  fi
else
  echo "warning: missing system packages: ${missing[*]} (install them with your package manager; until then what needs them is skipped or fails with a message)" >&2
fi
