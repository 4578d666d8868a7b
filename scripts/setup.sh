#!/usr/bin/env bash
# Installs the Debian 12 packages omnisculpt needs (only those missing) and builds it in Release.
# Usage: scripts/setup.sh [--no-build] [--with-test-packages]
#   --with-test-packages  also the packages only the tests need (scripts/test.sh passes it): Slurm
#                         and MUNGE for the local one-node cluster of tests/slurm/.
# Environment: BUILD_DIR (default build), OMNI_JOBS (default: all cores).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"

build=1
test_packages=0
for arg in "$@"; do
  case "$arg" in
    --no-build) build=0 ;;
    --with-test-packages) test_packages=1 ;;
    *) echo "omnisculpt setup: error: unknown option '$arg' (--no-build, --with-test-packages)" >&2; exit 2 ;;
  esac
done

packages=(
  build-essential cmake ninja-build ccache pkg-config git
  libeigen3-dev libopencv-dev libceres-dev libcgal-dev libgmp-dev libmpfr-dev libtbb-dev
  libopengv-dev libembree-dev libcli11-dev nlohmann-json3-dev libspdlog-dev libfmt-dev libyaml-cpp-dev
  zlib1g-dev libdeflate-dev
  libgtest-dev libgmock-dev libbenchmark-dev gnuplot-nox
  clang libclang-rt-14-dev e2fsprogs
  time  # /usr/bin/time -v: peak RSS in scripts/bench.sh
)
# The web viewer (`omnisculpt view`): npm installs the pinned three.js of viewer/package-lock.json
# at build time (into the build folder); its browser test runs Debian's chromium, headless.
# Node and npm count as present when their commands are (a node from elsewhere brings npm).
command -v node >/dev/null 2>&1 || packages+=(nodejs)
command -v npm >/dev/null 2>&1 || packages+=(npm)
command -v chromium >/dev/null 2>&1 || packages+=(chromium fonts-liberation)
# Test-only: the cluster test (tests/slurm/) starts a one-node Slurm cluster on localhost
# (scripts/slurm/local_cluster.sh): slurmctld, slurmd, the client commands and munged; python3
# reads the evaluations there.
if [ "$test_packages" = 1 ]; then
  packages+=(slurm-wlm slurmctld slurmd slurm-client munge python3)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "omnisculpt setup: installing ${#missing[@]} missing Debian packages: ${missing[*]}"
  if [ "$(id -u)" -eq 0 ]; then sudo_cmd=(); else sudo_cmd=(sudo); fi
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -qq
  "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

[ "$build" = 0 ] && exit 0

build_dir="${BUILD_DIR:-build}"
jobs="${OMNI_JOBS:-$(nproc)}"
launcher=()
if command -v ccache >/dev/null 2>&1; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
if [ ! -f "$build_dir/CMakeCache.txt" ]; then
  cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release "${launcher[@]}"
fi
cmake --build "$build_dir" -j "$jobs"
