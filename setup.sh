#!/usr/bin/env bash
# Installs whatever stylize3d still lacks on this machine, then returns quickly on
# later runs. Debian (or Ubuntu) with Python >= 3.10; no GPU needed.
#   1. the Debian libraries Open3D needs (and Xvfb for the window tests, Chromium for the web-page test),
#   2. a virtual environment in .venv,
#   3. torch as the local CPU build (torch==2.13.0, never a multi-GB CUDA build),
#   4. stylize3d itself (editable) with its test dependencies.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"

# chromium and chromium-driver: the browser test of the web-page export (tests/export/test_web_page.py).
DEBIAN_PACKAGES=(libusb-1.0-0 libvulkan1 mesa-vulkan-drivers libgl1 libegl1 libgomp1 xvfb xauth chromium chromium-driver)
TORCH_REQUIREMENT="torch==2.13.0"

missing=()
if command -v dpkg-query >/dev/null 2>&1; then
  for pkg in "${DEBIAN_PACKAGES[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
      missing+=("$pkg")
    fi
  done
else
  echo "setup.sh: dpkg-query not found; this script expects Debian or Ubuntu." >&2
  echo "          Install the equivalents of: ${DEBIAN_PACKAGES[*]}" >&2
  exit 1
fi

if ((${#missing[@]})); then
  if [ "$(id -u)" = 0 ]; then
    echo "setup.sh: installing Debian packages: ${missing[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
    echo "setup.sh: installing Debian packages with sudo: ${missing[*]}"
    sudo apt-get update -qq
    sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "setup.sh: stylize3d needs these Debian packages, which are not installed:" >&2
    echo "    ${missing[*]}" >&2
    echo "Ask an administrator to run:" >&2
    echo "    sudo apt-get install ${missing[*]}" >&2
    exit 1
  fi
fi

PYTHON="${PYTHON:-python3}"
if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 10))'; then
  echo "setup.sh: stylize3d needs Python >= 3.10; $PYTHON is $("$PYTHON" --version 2>&1)" >&2
  exit 1
fi
if [ ! -x .venv/bin/python ]; then
  echo "setup.sh: creating the virtual environment .venv"
  "$PYTHON" -m venv .venv
fi

# Re-install only when the project's requirements changed since the last run.
stamp=.venv/.stylize3d-setup
want="$(cat pyproject.toml setup.sh | sha256sum | cut -c1-16)"
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "setup.sh: installing Python packages into .venv (first run takes a few minutes)"
  # torch first and pinned, so no later requirement can pull a CUDA build.
  .venv/bin/python -m pip install -q "$TORCH_REQUIREMENT"
  .venv/bin/python -m pip install -q -e ".[test]"
  echo "$want" > "$stamp"
fi
