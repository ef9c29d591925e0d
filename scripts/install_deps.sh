#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Installs every Debian 12 package aneuclip needs to build, test and run (compiler and CMake included).
# Idempotent: packages already present are left alone, and when nothing is missing apt is not touched.
# Works as root without sudo, and as a user with sudo.
set -euo pipefail

PACKAGES=(
  # toolchain
  build-essential cmake ninja-build ccache pkg-config git ca-certificates
  # core: linear algebra, I/O, CLI, logging, tests
  libeigen3-dev libhdf5-dev libsuitesparse-dev libopenblas-dev liblapack-dev
  libcli11-dev nlohmann-json3-dev libspdlog-dev libfmt-dev libssl-dev zlib1g-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  # simulator: the OpenIGTLink device and viewer interface (aneusim serve)
  libopenigtlink-dev
  # pipeline: imaging and meshing
  libinsighttoolkit5-dev libgdcm-dev libgdcm-tools libvtk9-dev
  libcgal-dev libgmp-dev libmpfr-dev libboost-dev
  libnglib-dev netgen libtet1.5-dev
  # residual blood flow (aneuprep flow): OpenFOAM's blockMesh, snappyHexMesh and simpleFoam, run as child processes
  openfoam
  # off-screen rendering for snapshots (Debian's VTK renders through X11 only)
  xvfb xauth
  # workflow checks: CalculiX (the exported .inp is run in ccx) and headless Chromium (the QA report)
  calculix-ccx chromium
  # the batch test finds the running stage with pgrep (procps is not in minimal Debian images)
  procps
  # the real-data corpus test reads each case's QA (inspect --json) with python3; the bad-input test writes
  # a float volume with perl (perl-base is essential, but say what is used)
  python3 perl
  # the benchmarks measure peak memory with GNU time (/usr/bin/time; not in minimal Debian images)
  time
)

if [ "$(id -u)" -eq 0 ]; then
  SUDO=()
elif command -v sudo >/dev/null 2>&1; then
  SUDO=(sudo)
else
  echo "install_deps.sh: error: not root and sudo is not available; run as root or install sudo" >&2
  exit 2
fi

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps.sh: all ${#PACKAGES[@]} packages present"
  exit 0
fi

echo "install_deps.sh: installing ${#missing[@]} missing package(s): ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${SUDO[@]}" apt-get update -q
"${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
