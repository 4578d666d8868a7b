#!/usr/bin/env bash
# Installs what is missing, builds omnisculpt (Release, all cores) and runs the main job on the
# built-in default drive: the `demo` synthetic city (made once, then reused), its surface, and
# the evaluation against ground truth. Output goes to out/ (override with OMNI_OUT).
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

# The in-process SfM + surface pipeline (`omnisculpt reconstruct`) is not built yet; until it
# is, the surface is sculpted from a simulated perfect SfM on the drive's ground truth.
rec="$out/demo-from-gt"
rm -rf "$rec.previous"
[ -d "$rec" ] && mv "$rec" "$rec.previous"
"$omni" surface --from-gt "$drive" --out "$rec"
"$omni" mesh-check "$rec/surface.ply" || true
"$omni" eval --gt "$drive" --rec "$rec"

echo
echo "drive:   $drive (images/, gt/)"
echo "surface: $rec/surface.ply"
echo "report:  $rec/report/report.md (renders and plots beside it)"
