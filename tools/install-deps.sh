#!/usr/bin/env bash
# Install the Debian packages OpenBokeh needs, only those missing; quiet when none is.
# Run as root (CI, a fresh machine) or with sudo available.
set -euo pipefail

packages=(
  build-essential cmake pkg-config ccache
  libopenimageio-dev openimageio-tools libopenexr-dev openexr
  libopencolorio-dev opencolorio-tools libtbb-dev libglm-dev libfftw3-dev libdeflate-dev
  libgtest-dev libbenchmark-dev
  python3-matplotlib
  pybind11-dev python3-dev python3-numpy python3-openimageio python3-pytest
  libgegl-dev
  slurm-wlm munge
)

missing=()
for p in "${packages[@]}"; do
  status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
  [[ "$status" == "install ok installed" ]] || missing+=("$p")
done
[[ ${#missing[@]} -eq 0 ]] && exit 0

echo "Installing missing packages: ${missing[*]}"
sudo=""
if [[ $(id -u) -ne 0 ]]; then
  command -v sudo >/dev/null || { echo "install-deps: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
  sudo="sudo"
fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
