#!/usr/bin/env bash
# Installs what is missing (with the test-only packages: Slurm and MUNGE), builds omnisculpt (Release, all cores) and runs every test; then the
# unit tests again built with AddressSanitizer and UndefinedBehaviorSanitizer, and a short fuzz
# run of every parser (docs/errors.md).
# Environment: BUILD_DIR (default build), OMNI_SANITIZE_TESTS (default 1; 0 skips the sanitizer
# step, all adds the synth, sfm and surface unit tests to it), OMNI_FUZZ_SECONDS (seconds per parser, default 20; 0 skips the fuzzing).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
step_start=$SECONDS
bash scripts/setup.sh --with-test-packages
echo "test.sh: setup and build $((SECONDS - step_start)) s"
build_dir="${BUILD_DIR:-build}"
step_start=$SECONDS
ctest --test-dir "$build_dir" --output-on-failure -j "$(nproc)" --timeout 600
echo "test.sh: ctest $((SECONDS - step_start)) s"

if [ "${OMNI_SANITIZE_TESTS:-1}" != 0 ]; then
  # Unit tests built with ASan and UBSan at -O1 (Release otherwise: NDEBUG), in their own
  # folder; a finding aborts the program. By default calib (every reader of an input file),
  # raycast and eval, which fit the CI budget; OMNI_SANITIZE_TESTS=all adds synth, sfm and
  # surface (a long build and synth's slow renders: docs/errors.md).
  step_start=$SECONDS
  sanitize_dir="${build_dir}-sanitize"
  sanitize_targets=(calib_tests raycast_tests eval_tests)
  if [ "${OMNI_SANITIZE_TESTS:-1}" = all ]; then
    sanitize_targets+=(synth_tests sfm_tests surface_tests)
  fi
  launcher=()
  if command -v ccache >/dev/null 2>&1; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
  if [ ! -f "$sanitize_dir/CMakeCache.txt" ]; then
    cmake -S . -B "$sanitize_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE='-O1 -DNDEBUG' \
      -DOMNI_SANITIZE=address,undefined -DOMNI_BUILD_BENCHMARKS=OFF "${launcher[@]}" >/dev/null
  fi
  cmake --build "$sanitize_dir" -j "$(nproc)" --target "${sanitize_targets[@]}"
  echo "test.sh: sanitizer build $((SECONDS - step_start)) s"
  step_start=$SECONDS
  export ASAN_OPTIONS="abort_on_error=1:detect_leaks=1:strict_string_checks=1"
  export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
  for target in "${sanitize_targets[@]}"; do
    # The ShortDrive tests need the executable and its drive: they run in the plain build.
    "$sanitize_dir/tests/$target" --gtest_brief=1 --gtest_filter='-*ShortDrive*'
  done
  echo "test.sh: sanitizer tests $((SECONDS - step_start)) s"
fi

fuzz_seconds="${OMNI_FUZZ_SECONDS:-20}"
if [ "$fuzz_seconds" != 0 ]; then
  step_start=$SECONDS
  FUZZ_BUILD_DIR="${build_dir}-fuzz" bash scripts/fuzz.sh "$fuzz_seconds"
  echo "test.sh: fuzzing $((SECONDS - step_start)) s (build and $fuzz_seconds s per parser)"
fi
