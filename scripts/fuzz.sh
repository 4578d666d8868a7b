#!/usr/bin/env bash
# Fuzzes the parsers with libFuzzer (fuzz/, docs/design.md §4 "Fuzzing"): builds the harnesses
# with clang, AddressSanitizer and UndefinedBehaviorSanitizer in build-fuzz/ (only the parsers'
# sources) and runs each for SECONDS on a corpus seeded from the project's own files (fuzz/seeds/,
# data/rigs/, and the real drives' rig.json, poses.tum, frames.csv and images beside the
# repository when present). Fails on any crash, sanitizer report, leak, out-of-memory or input
# slower than 10 s. Prints per parser the executions, the coverage (edges) and the corpus size.
#
# Usage: scripts/fuzz.sh [SECONDS] [PARSER...]     (default 30 s each, every parser)
#   scripts/fuzz.sh 20                  the CI run
#   scripts/fuzz.sh 3600 ply colmap     a long run; the corpora grow in build-fuzz/corpus/<parser>
# Parsers: rig_json ply tum frames_csv image_file kalibr ladybug colmap.
# Environment: FUZZ_BUILD_DIR (default build-fuzz), OMNI_JOBS (default: all cores).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
seconds="${1:-30}"
shift || true
parsers=("$@")
[ ${#parsers[@]} -gt 0 ] || parsers=(rig_json ply tum frames_csv image_file kalibr ladybug colmap)
build_dir="${FUZZ_BUILD_DIR:-build-fuzz}"
jobs="${OMNI_JOBS:-$(nproc)}"

if [ ! -f "$build_dir/CMakeCache.txt" ]; then
  launcher=()
  if command -v ccache >/dev/null 2>&1; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
  cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ \
    -DOMNI_FUZZ=ON -DOMNI_BUILD_TESTS=OFF -DOMNI_BUILD_BENCHMARKS=OFF "${launcher[@]}" >/dev/null
fi
cmake --build "$build_dir" -j "$jobs" --target fuzzers

real="$here/../shared/data/real"
seed() {  # seed PARSER: copies the project's files of that format into the corpus
  local corpus="$build_dir/corpus/$1"
  mkdir -p "$corpus"
  [ -d "fuzz/seeds/$1" ] && cp fuzz/seeds/"$1"/* "$corpus"/
  case "$1" in
    rig_json) cp data/rigs/*.json "$corpus"/
              for f in "$real"/*/rig.json; do [ -f "$f" ] && cp "$f" "$corpus/real_$(basename "$(dirname "$f")").json"; done ;;
    tum) for f in "$real"/*/gt/poses.tum; do [ -f "$f" ] && cp "$f" "$corpus/real_$(basename "$(dirname "$(dirname "$f")")").tum"; done ;;
    frames_csv) for f in "$real"/*/frames.csv; do [ -f "$f" ] && cp "$f" "$corpus/real_$(basename "$(dirname "$f")").csv"; done ;;
    image_file) for f in "$real"/hilti*/images/cam0/000000.jpg; do [ -f "$f" ] && cp "$f" "$corpus/real.jpg"; done ;;
  esac
  return 0
}

status=0
summary=()
for parser in "${parsers[@]}"; do
  seed "$parser"
  log="$build_dir/fuzz_$parser.log"
  artifacts="$build_dir/artifacts/$parser/"
  mkdir -p "$artifacts"
  if "$build_dir/fuzz/fuzz_$parser" "$build_dir/corpus/$parser" -max_total_time="$seconds" \
      -timeout=10 -rss_limit_mb=2048 -max_len=65536 -print_final_stats=1 \
      -artifact_prefix="$artifacts" >"$log" 2>&1; then
    result=ok
  else
    result=FAILED
    status=1
    echo "fuzz: $parser FAILED; the end of $log:" >&2
    tail -n 40 "$log" >&2
  fi
  execs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)"
  cov="$(grep -o 'cov: [0-9]*' "$log" | tail -1 | sed 's/cov: //')"
  corpus_size="$(find "$build_dir/corpus/$parser" -type f | wc -l)"
  summary+=("$(printf '%-11s %-6s %10s executions in %s s, coverage %5s edges, corpus %s inputs' \
    "$parser" "$result" "${execs:-?}" "$seconds" "${cov:-?}" "$corpus_size")")
done
printf 'fuzz: %s\n' "${summary[@]}"
exit "$status"
