#!/usr/bin/env bash
# Install the Debian packages OpenBokeh needs, only those missing; quiet when none is.
# Run as root (CI, a fresh machine) or with sudo available.
#
#   install-deps.sh        everything: the tool, the tests, the benches, Python, the farm test
#   install-deps.sh tool   the library, bokehtool and its plugins only (what make demo needs)
set -euo pipefail

# Building and running the library and bokehtool. openimageio-tools too: Debian's
# OpenImageIO CMake package names its programs (/usr/bin/iconvert, ...) as imported
# targets and refuses to configure without them (seen on a fresh debootstrap'd bookworm).
packages=(
  build-essential cmake pkg-config ccache
  libopenimageio-dev openimageio-tools libopenexr-dev libopencolorio-dev libtbb-dev libglm-dev
  libfftw3-dev libdeflate-dev libnlopt-dev
)
case "${1:-all}" in
  tool) ;;
  all)
    packages+=(
      openexr opencolorio-tools                     # exrheader, ociocheck: peers in tests
      libgtest-dev libbenchmark-dev                 # unit tests, microbenchmarks
      python3-matplotlib                            # the bench charts
      pybind11-dev python3-dev python3-numpy python3-openimageio python3-pytest  # Python
      libgegl-dev                                   # a bench peer
      slurm-wlm munge                               # the farm test
    )
    ;;
  *) echo "usage: $0 [tool|all]" >&2; exit 2 ;;
esac

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
