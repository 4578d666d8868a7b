#!/usr/bin/env bash
# Installs what is missing, builds omnisculpt (Release, all cores) and runs the main job on the
# built-in default drive: the `demo` synthetic city (made once, then reused), its reconstruction
# (`omnisculpt reconstruct`: SfM and surface in one process) and the evaluation against ground
# truth. Output goes to out/ (override with OMNI_OUT).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/setup.sh
build_dir="${BUILD_DIR:-build}"
out="${OMNI_OUT:-out}"
omni="$build_dir/omnisculpt"
mkdir -p "$out/drives"

drive="$out/drives/demo"
if [ ! -f "$drive/gt/scene.json" ]; then
  "$omni" synth --preset demo --out "$drive"
fi

# The whole job in one process: SfM and incremental surface on their own threads
# (`omnisculpt reconstruct`), then the evaluation against the drive's ground truth. --force
# replaces only a previous reconstruction (a folder with reconstruct.json), nothing else.
rec="$out/demo"
"$omni" reconstruct "$drive" --out "$rec" --force
"$omni" eval --gt "$drive" --rec "$rec"

echo
echo "drive:   $drive (images/, gt/)"
echo "mesh:    $rec/surface.ply (points.ply, poses.tum, stats/keyframes.csv beside it)"
echo "renders: $rec/report/*.png (bird's-eye and keyframe views, estimated and ground truth)"
echo "report:  $rec/report/report.md (error quantiles, trajectory, per-keyframe times)"
