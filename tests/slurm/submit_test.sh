#!/usr/bin/env bash
# scripts/slurm/submit.sh without a cluster: a fake sbatch on PATH records each submission.
#   * the cut: K segments [a_k, b_k) with a_0 = 0, b_(K-1) = N, each sharing exactly F frames
#     with the next, lengths within one frame of each other, in SHARED/segments.tsv;
#   * the submissions: an array --array=0-(K-1) of segment_job.sh, then merge_job.sh with
#     --dependency=afterany:<the array's id>; the ids in SHARED/jobs.env;
#   * bad input: one line on stderr naming the problem, exit 2, nothing left in SHARED (no drive,
#     no rig.json, bad --segments, --overlap 0 or too large, SHARED not empty, sbatch missing,
#     sbatch refusing the job).
# Usage: submit_test.sh --scripts SCRIPTS_SLURM_DIR --work DIR
set -uo pipefail
me="slurm_submit"
failures=0
check() {  # check DESCRIPTION CONDITION...
  local what="$1"
  shift
  if "$@"; then echo "ok: $what"; else echo "FAIL: $me: $what"; failures=$((failures + 1)); fi
}

scripts="" work=""
while [ $# -gt 0 ]; do
  case "$1" in
    --scripts) scripts="$2"; shift 2 ;;
    --work) work="$2"; shift 2 ;;
    *) echo "FAIL: $me: unknown argument '$1'"; exit 1 ;;
  esac
done
submit="$scripts/submit.sh"
[ -f "$submit" ] || { echo "FAIL: $me: --scripts '$scripts': no submit.sh"; exit 1; }
rm -rf "$work" && mkdir -p "$work" && work="$(cd "$work" && pwd)"

# A drive as submit.sh sees it: rig.json's first camera and its images (never decoded here).
frames=103
drive="$work/drive"
mkdir -p "$drive/images/front" "$drive/images/back"
echo '{"cameras": [{"name": "front"}, {"name": "back"}]}' >"$drive/rig.json"
for ((i = 0; i < frames; i++)); do
  name="$(printf '%06d' "$i")"
  : >"$drive/images/front/$name.png"
  : >"$drive/images/back/$name.png"
done
: >"$drive/images/front/notes.txt"  # not an image
omnisculpt="$work/omnisculpt"
printf '#!/bin/sh\nexit 0\n' >"$omnisculpt"
chmod +x "$omnisculpt"

# The fake sbatch: appends its arguments (one per line, then ---) to $FAKE_SBATCH_LOG and prints
# the next job id, as --parsable does; FAKE_SBATCH_REFUSE=1 makes it refuse.
bin="$work/bin"
mkdir -p "$bin"
cat >"$bin/sbatch" <<'SB'
#!/usr/bin/env bash
if [ "${FAKE_SBATCH_REFUSE:-0}" = 1 ]; then echo "sbatch: error: Invalid partition name specified" >&2; exit 1; fi
printf '%s\n' "$@" --- >>"$FAKE_SBATCH_LOG"
n=$(grep -c '^---$' "$FAKE_SBATCH_LOG")
echo "$((4100 + n));cluster"
SB
printf '#!/bin/sh\nexit 0\n' >"$bin/scancel"
chmod +x "$bin/sbatch" "$bin/scancel"

# --- a submission ---
export FAKE_SBATCH_LOG="$work/sbatch.log"
segments=4
overlap=9
shared="$work/shared"
out="$(PATH="$bin:$PATH" bash "$submit" "$drive" "$shared" --segments "$segments" --overlap "$overlap" \
  --cpus-per-task 3 --omnisculpt "$omnisculpt" --partition batch --time 10 --profile accurate 2>&1)"
code=$?
echo "$out"
check "a good submission exits 0" [ "$code" = 0 ]
check "two sbatch calls" [ "$(grep -c '^---$' "$FAKE_SBATCH_LOG" 2>/dev/null)" = 2 ]

cut_ok() {
  awk -F'\t' -v n="$frames" -v f="$overlap" -v k="$segments" '
    NR == 1 { next }
    { seg[NR - 2] = $1; a[NR - 2] = $2; b[NR - 2] = $3; rows++ }
    END {
      if (rows != k) { print "rows " rows " != " k; exit 1 }
      if (a[0] != 0 || b[k - 1] != n) { print "not 0.." n ": " a[0] ".." b[k - 1]; exit 1 }
      min = n; max = 0
      for (i = 0; i < k; i++) {
        if (seg[i] != i) { print "segment " i " named " seg[i]; exit 1 }
        len = b[i] - a[i]; if (len < min) min = len; if (len > max) max = len
        if (i + 1 < k && b[i] - a[i + 1] != f) { print "segments " i "," i + 1 " share " b[i] - a[i + 1]; exit 1 }
        if (i + 2 < k && b[i] > a[i + 2]) { print "segments " i "," i + 2 " overlap"; exit 1 }
      }
      if (max - min > 1) { print "lengths " min ".." max; exit 1 }
    }' "$shared/segments.tsv"
}
check "segments.tsv: $segments segments of $frames frames, each sharing $overlap with the next" cut_ok
first_call="$(awk '/^---$/ { exit } { print }' "$FAKE_SBATCH_LOG")"
second_call="$(awk 'seen { print } /^---$/ { seen = 1 }' "$FAKE_SBATCH_LOG" | sed '/^---$/d')"
has() { grep -qxF -- "$2" <<<"$1"; }
check "the array: --array=0-$((segments - 1))" has "$first_call" "--array=0-$((segments - 1))"
check "the array: --parsable" has "$first_call" "--parsable"
check "the array: --cpus-per-task=3, --partition=batch, --time=10" \
  bash -c 'grep -qxF -- --cpus-per-task=3 <<<"$1" && grep -qxF -- --partition=batch <<<"$1" && grep -qxF -- --time=10 <<<"$1"' _ "$first_call"
check "the array runs segment_job.sh OMNISCULPT DRIVE SHARED PROFILE" \
  bash -c 'grep -A4 "segment_job.sh$" <<<"$1" | tail -n 4 | tr "\n" " " | grep -qF -- "$2 $3 $4 accurate "' _ "$first_call" "$omnisculpt" "$drive" "$shared"
check "the merge: --dependency=afterany:4101 (the array's id without ;cluster)" has "$second_call" "--dependency=afterany:4101"
check "the merge runs merge_job.sh OMNISCULPT SHARED" \
  bash -c 'grep -A2 "merge_job.sh$" <<<"$1" | tail -n 2 | tr "\n" " " | grep -qF -- "$2 $3 "' _ "$second_call" "$omnisculpt" "$shared"
check "jobs.env holds both ids" bash -c 'grep -qx ARRAY_JOB=4101 "$1" && grep -qx MERGE_JOB=4102 "$1"' _ "$shared/jobs.env"
check "the job ids are printed" bash -c 'grep -q "array job 4101" <<<"$1" && grep -q "merge job 4102" <<<"$1"' _ "$out"

# --- bad input: one line on stderr, exit 2, SHARED not made ---
refuses() {  # refuses DESCRIPTION EXPECTED_TEXT [ENV=VALUE...] -- ARGS...
  local what="$1" expected="$2" envs=() err code
  shift 2
  while [ "$1" != -- ]; do envs+=("$1"); shift; done
  shift
  rm -rf "$work/bad_shared"
  err="$(env "${envs[@]}" bash "$submit" "$@" 2>&1 >/dev/null)"
  code=$?
  if [ "$code" = 2 ] && [ "$(printf '%s\n' "$err" | wc -l)" = 1 ] && grep -qF -- "$expected" <<<"$err" &&
    [ ! -e "$work/bad_shared" ]; then
    echo "ok: $what: $err"
  else
    echo "FAIL: $me: $what: exit $code, stderr: $err"
    failures=$((failures + 1))
  fi
}
good=("$drive" "$work/bad_shared" --omnisculpt "$omnisculpt" --overlap 9)
refuses "no drive" "no such drive folder" "PATH=$bin:$PATH" -- "$work/nowhere" "$work/bad_shared" --omnisculpt "$omnisculpt"
mkdir -p "$work/no_rig/images/front"
refuses "no rig.json" "rig.json: missing" "PATH=$bin:$PATH" -- "$work/no_rig" "$work/bad_shared" --omnisculpt "$omnisculpt"
refuses "--segments 0" "--segments" "PATH=$bin:$PATH" -- "${good[@]}" --segments 0
refuses "--segments x" "--segments" "PATH=$bin:$PATH" -- "${good[@]}" --segments x
refuses "--overlap 0" "--overlap 0" "PATH=$bin:$PATH" -- "${good[@]}" --overlap 0
refuses "--profile fast" "--profile" "PATH=$bin:$PATH" -- "${good[@]}" --profile fast
# 4 segments of 103 frames overlapping by 21: stride (103 - 21) / 4 = 20 < 21.
refuses "--overlap larger than the stride" "--overlap 21: too large" "PATH=$bin:$PATH" -- "${good[@]}" --overlap 21
refuses "--overlap beyond the drive" "--overlap 500" "PATH=$bin:$PATH" -- "${good[@]}" --overlap 500
refuses "--segments too many" "--segments 200" "PATH=$bin:$PATH" -- "${good[@]}" --segments 200 --overlap 1
refuses "SHARED not empty" "not empty" "PATH=$bin:$PATH" -- "$drive" "$shared" --omnisculpt "$omnisculpt" --overlap 9
refuses "sbatch refusing the array" "sbatch refused" "PATH=$bin:$PATH" FAKE_SBATCH_REFUSE=1 -- "${good[@]}"
# A PATH with the tools submit.sh uses but no sbatch.
nobin="$work/no_sbatch_bin"
mkdir -p "$nobin"
ln -sf "$(python3 -c 'import sys; print(sys.executable)')" "$nobin/python3"
for tool in bash env find wc ls cat mkdir rmdir rm date dirname basename tr awk sed tail grep; do
  ln -sf "$(command -v "$tool")" "$nobin/$tool"
done
refuses "sbatch missing" "sbatch not found" "PATH=$nobin" -- "${good[@]}"

if [ "$failures" -gt 0 ]; then
  echo "FAIL: $me: $failures check(s) failed"
  exit 1
fi
echo "$me: all checks passed"
