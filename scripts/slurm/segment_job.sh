#!/usr/bin/env bash
# Slurm batch script: one segment of a drive, one task of the array that scripts/slurm/submit.sh
# submits (sbatch --array=0-(K-1) segment_job.sh OMNISCULPT DRIVE SHARED [PROFILE]).
# Task k reads its row "k first end" of SHARED/segments.tsv (frames first..end-1 of the drive,
# by their index in the drive) and runs
#   OMNISCULPT reconstruct DRIVE --frames first:end --out SHARED/segments/k --force --profile PROFILE
# (--force: a requeued task replaces its own earlier reconstruction; PROFILE is realtime when not
# given). It writes SHARED/timing/segment_k.tsv (start and end, seconds since the epoch, the
# exit code, the node) and exits with reconstruct's exit code, so a failed segment shows as
# FAILED in Slurm; the merge job runs after the array whatever happened (afterany) and reports
# what is missing.
#SBATCH --job-name=omni-segment
set -uo pipefail
me="segment_job.sh"
if [ $# -ne 3 ] && [ $# -ne 4 ]; then
  echo "$me: error: usage: sbatch --array=0-(K-1) $me OMNISCULPT DRIVE SHARED [PROFILE]" >&2
  exit 2
fi
omnisculpt="$1" drive="$2" shared="$3" profile="${4:-realtime}"
task="${SLURM_ARRAY_TASK_ID:-}"
if [ -z "$task" ]; then
  echo "$me: error: SLURM_ARRAY_TASK_ID is not set (submit it as an array: scripts/slurm/submit.sh)" >&2
  exit 2
fi
segments_file="$shared/segments.tsv"
row="$(awk -F'\t' -v k="$task" 'NR > 1 && $1 == k { print $2 " " $3 }' "$segments_file" 2>/dev/null)"
if [ -z "$row" ]; then
  echo "$me: error: $segments_file: no row for segment $task" >&2
  exit 2
fi
read -r first end <<<"$row"
out="$shared/segments/$task"
mkdir -p "$shared/segments" "$shared/timing"
start="$(date +%s.%N)"
echo "$me: segment $task: frames $first:$end of $drive -> $out on $(hostname -s), job ${SLURM_JOB_ID:-?}, ${SLURM_CPUS_PER_TASK:-?} CPUs, profile $profile"
"$omnisculpt" reconstruct "$drive" --frames "$first:$end" --out "$out" --force --profile "$profile"
code=$?
end_time="$(date +%s.%N)"
printf 'start\tend\texit_code\tnode\n%s\t%s\t%s\t%s\n' "$start" "$end_time" "$code" "$(hostname -s)" \
  >"$shared/timing/segment_$task.tsv"
echo "$me: segment $task: exit code $code after $(awk -v a="$start" -v b="$end_time" 'BEGIN { printf "%.1f", b - a }') s"
exit "$code"
