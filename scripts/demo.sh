#!/usr/bin/env bash
# Installs what is missing, builds omnisculpt (Release, all cores) and runs the main job on the
# built-in default drive. Output goes to out/ (override with OMNI_OUT).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/setup.sh
build_dir="${BUILD_DIR:-build}"
out="${OMNI_OUT:-out}"
omni="$build_dir/omnisculpt"
mkdir -p "$out"

"$omni" calib show --default
