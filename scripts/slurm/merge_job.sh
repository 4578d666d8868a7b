#!/usr/bin/env bash
# Slurm batch script: the merge of a drive's segments, submitted by scripts/slurm/submit.sh
# after the segments' array (--dependency=afterany: it runs whether or not every segment
# succeeded). It runs
#   OMNISCULPT merge SHARED/segments/0 ... SHARED/segments/K-1 --out SHARED/city --force
# (--force: a merge submitted again replaces the earlier one) naming every segment of SHARED/segments.tsv, so one that failed or never ran is reported in
# SHARED/city/merge.json ("missing") and on stderr while the others are merged. It writes
# SHARED/timing/merge.tsv (start, end, exit code, node) and exits with merge's exit code.
#SBATCH --job-name=omni-merge
set -uo pipefail
me="merge_job.sh"
if [ $# -ne 2 ]; then
  echo "$me: error: usage: sbatch $me OMNISCULPT SHARED" >&2
  exit 2
fi
omnisculpt="$1" shared="$2"
segments_file="$shared/segments.tsv"
segments=()
while IFS=$'\t' read -r k _; do
  segments+=("$shared/segments/$k")
done < <(tail -n +2 "$segments_file" 2>/dev/null)
if [ ${#segments[@]} -eq 0 ]; then
  echo "$me: error: $segments_file: no segments" >&2
  exit 2
fi
mkdir -p "$shared/timing"
start="$(date +%s.%N)"
echo "$me: merging ${#segments[@]} segments -> $shared/city on $(hostname -s), job ${SLURM_JOB_ID:-?}"
"$omnisculpt" merge "${segments[@]}" --out "$shared/city" --force
code=$?
end_time="$(date +%s.%N)"
printf 'start\tend\texit_code\tnode\n%s\t%s\t%s\t%s\n' "$start" "$end_time" "$code" "$(hostname -s)" \
  >"$shared/timing/merge.tsv"
echo "$me: exit code $code after $(awk -v a="$start" -v b="$end_time" 'BEGIN { printf "%.1f", b - a }') s"
exit "$code"
