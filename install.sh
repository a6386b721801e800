#!/usr/bin/env bash
# Installs recon and everything it needs on Debian 12 with Python >= 3.11:
# Debian libraries (Open3D needs libusb-1.0; MuJoCo's offscreen rendering needs EGL/Mesa),
# then the Python packages from PyPI, with recon itself in editable mode.
#   --franka-sim   also build franka-sim's own environment (.venvs/franka-sim), the stand-in
#                  Franka the tests drive through pylibfranka (it pins numpy 1.26 and MuJoCo < 3.3)
set -euo pipefail
FRANKA_SIM=0
for arg in "$@"; do
  case "$arg" in
    --franka-sim) FRANKA_SIM=1 ;;
    *) echo "install.sh: unknown option $arg (known: --franka-sim)" >&2; exit 2 ;;
  esac
done
cd "$(dirname "$0")"

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
PY="${PYTHON:-python3}"

echo "== Debian packages"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
  libusb-1.0-0 libegl1 libegl-mesa0 libgl1 libgomp1 >/dev/null

echo "== Python packages"
# Debian's own Python marks itself externally managed (PEP 668); recon then goes into it anyway
if "$PY" -c 'import sys, sysconfig, pathlib; sys.exit(0 if (pathlib.Path(sysconfig.get_path("stdlib")) / "EXTERNALLY-MANAGED").exists() else 1)'; then
  export PIP_BREAK_SYSTEM_PACKAGES=1
fi
"$PY" -m pip install -q --disable-pip-version-check -e ".[dev]"
echo "== recon installed: $(command -v recon || echo "$PY -m recon_cli")"

if [ "$FRANKA_SIM" = 1 ]; then
  echo "== franka-sim stand-in (.venvs/franka-sim)"
  "$PY" -m venv .venvs/franka-sim
  .venvs/franka-sim/bin/python -m pip install -q --disable-pip-version-check "franka-sim==1.1.7"
fi
