#!/usr/bin/env bash
# Installs every Debian package inhand needs (idempotent). Run as root on Debian 12.
set -euo pipefail
packages=(
  build-essential cmake ninja-build pkg-config
  libeigen3-dev libembree-dev libtbb-dev libassimp-dev libpng-dev libjpeg-dev
  nlohmann-json3-dev libcli11-dev
  liburdfdom-dev libsdformat-dev liborocos-kdl-dev libfcl-dev libmujoco-dev
  libgtest-dev libbenchmark-dev
  clang libclang-rt-14-dev clang-format
  python3-dev pybind11-dev python3-numpy python3-pytest
  nodejs npm chromium
)
# Slurm for `inhand eval --backend slurm` on a single-node cluster of this machine
# (scripts/slurm-local.sh) and its test: only when asked.
if [ "${INHAND_WITH_SLURM:-0}" = 1 ]; then
  packages+=(slurmctld slurmd slurm-client munge)
fi
# Open3D for bench/bench_open3d (the integration benchmark against it): only when asked.
if [ "${INHAND_WITH_OPEN3D:-0}" = 1 ]; then
  packages+=(libopen3d-dev)
fi
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
# A machine that already has Node.js (from its own distribution) needs no Debian npm.
if command -v node > /dev/null && command -v npm > /dev/null; then
  kept=()
  for p in "${missing[@]}"; do [ "$p" = nodejs ] || [ "$p" = npm ] || kept+=("$p"); done
  missing=("${kept[@]+"${kept[@]}"}")
fi
if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps: all Debian packages present"
else
  echo "install_deps: installing ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y --no-install-recommends "${missing[@]}"
fi
# The report's front-end libraries (three.js, Chart.js), pinned by web/package-lock.json.
web="$(cd "$(dirname "$0")/../web" && pwd)"
if [ ! -f "$web/node_modules/three/package.json" ] || [ ! -f "$web/node_modules/chart.js/package.json" ] ||
   [ "$web/package-lock.json" -nt "$web/node_modules/.package-lock.json" ]; then
  echo "install_deps: npm ci in $web"
  (cd "$web" && npm ci --no-audit --no-fund)
fi
