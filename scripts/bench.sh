#!/usr/bin/env bash
# The speed benchmark of the whole program on one machine: makes the drives it needs once (the
# `demo` synthetic drive, and the `short` drive on the `car` rig for the sfm_car case), runs each
# case with a Release build and prints one table (scripts/bench_summary.py): frames/s, SfM ms per
# frame and stage, surface ms per keyframe (median, p95, flatness), peak RSS (and per 1000
# frames), the machine (CPU, cores, load average) and the drives.
#
# usage: scripts/bench.sh [--build DIR] [--compare OTHER_BUILD_DIR] [--rounds N]
#                         [--cases LIST] [--eval] [--drives DIR] [--out DIR] [--no-build]
#
#   --build DIR      the build measured (default build; A in the table): a build folder, or a
#                    folder holding a copied omnisculpt (its commit in DIR/bench_commit.txt)
#   --compare DIR    a second build (B), run alternated with A: A, B, A, B, ... and the table
#                    gives the ratios A / B of the medians
#   --rounds N       runs of every case per build (default 1, 2 with --compare)
#   --cases LIST     comma-separated, from (default: reconstruct,reconstruct_nc,sfm,surface)
#                      reconstruct     omnisculpt reconstruct --central on demo
#                      reconstruct_nc  the same with --non-central (the rig's true offsets)
#                      reconstruct_accurate, reconstruct_offline
#                                      reconstruct_nc with --profile accurate / offline
#                      sfm             omnisculpt sfm --central on demo
#                      sfm_nc          omnisculpt sfm --non-central on demo
#                      sfm_car         omnisculpt sfm on short with the car rig (non-central:
#                                      1-1.5 m offsets)
#                      surface         omnisculpt surface --from-gt on demo (the paper's density)
#   --eval           also omnisculpt eval on each reconstruct output (ATE, pixel F-score)
#   --drives DIR     where the drives are made once and reused (default out/bench/drives)
#   --out DIR        the runs' outputs (default out/bench/<date>)
#   --no-build       use the builds' omnisculpt as they are (default: bring each build folder
#                    that holds build.ninja up to date, target omnisculpt only)
#
# Peak RSS comes from /usr/bin/time (the `time` package, scripts/setup.sh) when present, else
# from python's resource.getrusage(RUSAGE_CHILDREN). Times are wall times of the whole command
# (start-up and output writing included); the per-stage figures come from the command's own
# stats/ files. Speeds are never asserted: compare builds with --compare on one machine.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"

build_a=build
build_b=""
rounds=""
cases="reconstruct,reconstruct_nc,sfm,surface"
with_eval=0
drives="out/bench/drives"
out=""
do_build=1
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build_a="$2"; shift 2 ;;
    --compare) build_b="$2"; shift 2 ;;
    --rounds) rounds="$2"; shift 2 ;;
    --cases) cases="$2"; shift 2 ;;
    --eval) with_eval=1; shift ;;
    --drives) drives="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --no-build) do_build=0; shift ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "bench.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
if ! [[ "${rounds:-1}" =~ ^[1-9][0-9]*$ ]]; then
  echo "bench.sh: --rounds: expected a positive count, got '$rounds'" >&2; exit 2
fi
[ -n "$rounds" ] || { [ -n "$build_b" ] && rounds=2 || rounds=1; }
IFS=, read -r -a case_list <<< "$cases"
for c in "${case_list[@]}"; do
  case "$c" in
    reconstruct|reconstruct_nc|reconstruct_accurate|reconstruct_offline|sfm|sfm_nc|sfm_car|surface) ;;
    *) echo "bench.sh: --cases: unknown case '$c' (see --help)" >&2; exit 2 ;;
  esac
done

builds=("$build_a")
[ -n "$build_b" ] && builds+=("$build_b")
for b in "${builds[@]}"; do
  if [ "$do_build" = 1 ] && [ -f "$b/build.ninja" ]; then
    cmake --build "$b" --target omnisculpt >/dev/null
  fi
  if [ ! -x "$b/omnisculpt" ]; then
    echo "bench.sh: $b/omnisculpt: no such program (build it: cmake --build $b --target omnisculpt)" >&2
    exit 2
  fi
  if [ -f "$b/CMakeCache.txt" ] && ! grep -q '^CMAKE_BUILD_TYPE:STRING=Release$' "$b/CMakeCache.txt"; then
    echo "bench.sh: warning: $b is not a Release build" >&2
  fi
done
omni_a="$build_a/omnisculpt"

# The drives, made once (synthetic drives are deterministic for their seed).
mkdir -p "$drives"
need_demo=0 need_car=0
for c in "${case_list[@]}"; do
  if [ "$c" = sfm_car ]; then need_car=1; else need_demo=1; fi
done
if [ "$need_demo" = 1 ] && [ ! -f "$drives/demo/gt/scene.json" ]; then
  echo "bench.sh: making the demo drive in $drives/demo (once)"
  "$omni_a" synth --preset demo --out "$drives/demo" --force >/dev/null
fi
if [ "$need_car" = 1 ] && [ ! -f "$drives/short_car/gt/scene.json" ]; then
  echo "bench.sh: making the short drive on the car rig in $drives/short_car (once)"
  "$omni_a" synth --preset short --rig-preset car --out "$drives/short_car" --force >/dev/null
fi

[ -n "$out" ] || out="out/bench/$(date -u +%Y%m%dT%H%M%SZ)"
mkdir -p "$out"
runs="$out/runs.tsv"
printf 'build\tlabel\tcase\tround\tdrive\tfolder\twall_s\tmax_rss_kb\texit\n' > "$runs"

# Machine, named in the table.
{
  echo "cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
  echo "nproc=$(nproc)"
  echo "load_start=$(cut -d' ' -f1-3 /proc/loadavg)"
  echo "date=$(date -u +%Y-%m-%dT%H:%M:%SZ)"
  for b in "${builds[@]}"; do
    src=$(sed -n 's/^CMAKE_HOME_DIRECTORY:INTERNAL=//p' "$b/CMakeCache.txt" 2>/dev/null || true)
    # A copied binary: the commit in a file beside it (bench_commit.txt), if any.
    commit=$( [ -n "$src" ] && git -C "$src" rev-parse --short HEAD 2>/dev/null ||
              cat "$b/bench_commit.txt" 2>/dev/null || echo unknown)
    dirty=$( [ -n "$src" ] && git -C "$src" status --porcelain --untracked-files=no 2>/dev/null | head -1 || true)
    [ -n "$dirty" ] && commit="$commit+changes"
    echo "build:$b=$commit"
  done
} > "$out/machine.txt"

have_time=0
[ -x /usr/bin/time ] && have_time=1

# Runs one command, its wall time and peak RSS appended to runs.tsv.
run_case() {  # build label case round
  local b="$1" label="$2" c="$3" r="$4"
  local omni="$b/omnisculpt" folder="$out/${label}_${c}_${r}" drive args=()
  case "$c" in
    reconstruct) drive="$drives/demo"; args=(reconstruct "$drive" --central --out "$folder") ;;
    reconstruct_nc) drive="$drives/demo"; args=(reconstruct "$drive" --non-central --out "$folder") ;;
    reconstruct_accurate|reconstruct_offline)
      drive="$drives/demo"
      args=(reconstruct "$drive" --non-central --profile "${c#reconstruct_}" --out "$folder") ;;
    sfm) drive="$drives/demo"; args=(sfm "$drive" --central --out "$folder") ;;
    sfm_nc) drive="$drives/demo"; args=(sfm "$drive" --non-central --out "$folder") ;;
    sfm_car) drive="$drives/short_car"; args=(sfm "$drive" --out "$folder") ;;
    surface) drive="$drives/demo"; args=(surface --from-gt "$drive" --out "$folder") ;;
  esac
  rm -rf "$folder"
  local log="$folder.log" timing="$folder.time" wall rss status=0
  echo "bench.sh: $label $c round $r: omnisculpt ${args[*]}"
  if [ "$have_time" = 1 ]; then
    /usr/bin/time -f '%e %M' -o "$timing" "$omni" "${args[@]}" > "$log" 2>&1 || status=$?
    read -r wall rss < <(tail -n 1 "$timing")
  else
    local result
    result=$(python3 -c '
import resource, subprocess, sys, time
start = time.monotonic()
with open(sys.argv[1], "w") as log:
    code = subprocess.call(sys.argv[2:], stdout=log, stderr=subprocess.STDOUT)
print(f"{time.monotonic() - start:.2f} {resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss} {code}")
' "$log" "$omni" "${args[@]}")
    read -r wall rss status <<< "$result"
  fi
  if [ "$status" != 0 ]; then
    echo "bench.sh: $label $c round $r exited with $status (see $log)" >&2
  fi
  if [ "$with_eval" = 1 ] && [ "$status" = 0 ] && [[ "$c" == reconstruct* ]]; then
    "$omni_a" eval --gt "$drive" --rec "$folder" --no-plots --no-renders > "$folder.eval.log" 2>&1 ||
      echo "bench.sh: eval of $folder failed (see $folder.eval.log)" >&2
  fi
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$b" "$label" "$c" "$r" "$drive" "$folder" \
    "$wall" "$rss" "$status" >> "$runs"
}

# A, B, A, B, ...: each case runs back to back on both builds, so that a change of the machine's
# load falls on both.
for ((r = 1; r <= rounds; ++r)); do
  for c in "${case_list[@]}"; do
    run_case "$build_a" A "$c" "$r"
    [ -n "$build_b" ] && run_case "$build_b" B "$c" "$r"
  done
done
echo "load_end=$(cut -d' ' -f1-3 /proc/loadavg)" >> "$out/machine.txt"

python3 scripts/bench_summary.py "$out" | tee "$out/table.md"
