#!/usr/bin/env bash
# The reconstruction's quality over several drives and starts, for one build and its options or
# two of them side by side: `omnisculpt reconstruct` then `omnisculpt eval` on each drive of a
# set (synthetic drives, made once), and one table (scripts/quality_summary.py) with every run's
# pixel F-scores, tail, error quantiles, the closed surface's and the keyframes' ATE, the recall
# and the share behind the truth of the pixels that see objects in front of the walls and the
# ground (trim, poles, trunks, crowns, cars: synth's labels, docs/figures.md F81), and their
# means per build (and the paired differences B − A).
#
# One run of one drive is not a measurement of a small change: a change of float rounding alone
# moves a run's pixel F@0.5 by about ±0.005 and its ATE by up to 1.7 times (docs/figures.md
# F57). Compare means over drives and starts.
#
# Usage: scripts/quality.sh [--build DIR] [--compare DIR] [--a-args "ARGS"] [--b-args "ARGS"]
#                           [--set LIST] [--starts N] [--drives DIR] [--out DIR]
#   --build DIR      build A (default: build), its omnisculpt used as it is
#   --compare DIR    build B (default: build A when --b-args is given, else none)
#   --a-args "ARGS"  extra reconstruct options of A (default none), split on spaces
#   --b-args "ARGS"  extra reconstruct options of B (default: A's)
#   --set LIST       comma-separated PRESET[:SEED] (default demo,demo:2,short,short:2,short:3);
#                    presets of omnisculpt synth (tiny, short, demo, paper)
#   --starts N       each drive also started 1 .. N − 1 frames later (--frames K:), default 1
#   --drives DIR     where the drives are made once and reused (default out/quality/drives)
#   --out DIR        the runs' outputs (default out/quality/<date>)
# Runs alternate A, B per drive and start. Exit 2 on bad arguments; 1 when a run failed.
set -euo pipefail

build_a="build" build_b="" args_a="" args_b="" have_args_b=0
set_list="demo,demo:2,short,short:2,short:3" starts=1 drives="out/quality/drives" out=""
usage() { sed -n '2,25p' "$0" | sed 's/^# \{0,1\}//'; }
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build_a="$2"; shift 2 ;;
    --compare) build_b="$2"; shift 2 ;;
    --a-args) args_a="$2"; shift 2 ;;
    --b-args) args_b="$2"; have_args_b=1; shift 2 ;;
    --set) set_list="$2"; shift 2 ;;
    --starts) starts="$2"; shift 2 ;;
    --drives) drives="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "quality.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[[ "$starts" =~ ^[1-9][0-9]*$ ]] || { echo "quality.sh: --starts: expected a positive count, got '$starts'" >&2; exit 2; }
[ "$have_args_b" = 1 ] && [ -z "$build_b" ] && build_b="$build_a"
[ "$have_args_b" = 0 ] && args_b="$args_a"
for b in "$build_a" ${build_b:+"$build_b"}; do
  [ -x "$b/omnisculpt" ] || { echo "quality.sh: $b/omnisculpt: no such program (build it first)" >&2; exit 2; }
done
IFS=, read -r -a entries <<< "$set_list"
for e in "${entries[@]}"; do
  [[ "$e" =~ ^(tiny|short|demo|paper)(:[0-9]+)?$ ]] ||
    { echo "quality.sh: --set: '$e' is not PRESET[:SEED] with a preset of tiny, short, demo, paper" >&2; exit 2; }
done
[ -n "$out" ] || out="out/quality/$(date -u +%Y%m%dT%H%M%SZ)"
mkdir -p "$drives" "$out"
runs="$out/runs.tsv"
printf 'build\tlabel\tdrive\tstart\tfolder\texit\n' > "$runs"
{
  echo "cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
  echo "date=$(date -u +%Y-%m-%dT%H:%M:%SZ)"
  echo "A=$build_a $args_a"
  [ -n "$build_b" ] && echo "B=$build_b $args_b"
} > "$out/machine.txt"

omni_a="$build_a/omnisculpt"
failed=0
for e in "${entries[@]}"; do
  preset="${e%%:*}" seed=""
  [[ "$e" == *:* ]] && seed="${e#*:}"
  name="$preset${seed:+_s$seed}"
  drive="$drives/$name"
  if [ ! -f "$drive/gt/scene.json" ]; then
    echo "quality.sh: making the $preset drive${seed:+ (seed $seed)} in $drive (once)"
    "$omni_a" --quiet synth --preset "$preset" ${seed:+--seed "$seed"} --out "$drive" --force >/dev/null
  fi
  for ((start = 0; start < starts; ++start)); do
    for label in A B; do
      if [ "$label" = A ]; then b="$build_a"; extra="$args_a"; else
        [ -n "$build_b" ] || continue; b="$build_b"; extra="$args_b"; fi
      folder="$out/${label}_${name}_${start}"
      frames=()
      [ "$start" -gt 0 ] && frames=(--frames "$start:")
      echo "quality.sh: $label $name start $start: omnisculpt reconstruct $drive ${frames[*]} $extra"
      status=0
      # shellcheck disable=SC2086  # the extra options are split on spaces on purpose
      "$b/omnisculpt" --quiet reconstruct "$drive" "${frames[@]}" $extra --out "$folder" --force \
        > "$folder.log" 2>&1 || status=$?
      if [ "$status" = 0 ]; then
        "$b/omnisculpt" eval --gt "$drive" --rec "$folder" --no-plots --no-renders \
          > "$folder.eval.log" 2>&1 || status=$?
      fi
      if [ "$status" != 0 ]; then
        echo "quality.sh: $label $name start $start failed (exit $status, see $folder.log)" >&2
        failed=1
      fi
      printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$b" "$label" "$name" "$start" "$folder" "$status" >> "$runs"
    done
  done
done
python3 "$(dirname "$0")/quality_summary.py" "$out" | tee "$out/summary.md"
exit "$failed"
