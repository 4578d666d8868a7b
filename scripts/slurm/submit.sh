#!/usr/bin/env bash
# Reconstructs a drive on a Slurm cluster: cuts it into K segments that overlap by F frames,
# reconstructs each as one task of an array job (scripts/slurm/segment_job.sh), then merges them
# into one map (scripts/slurm/merge_job.sh, after the array whatever its tasks' outcome).
#
# Usage: scripts/slurm/submit.sh DRIVE SHARED [--segments K] [--overlap F] [--cpus-per-task C]
#          [--mem-per-task M] [--omnisculpt PATH] [--partition P] [--time T] [--merge-time T]
#          [--profile realtime|accurate|offline]
#   DRIVE   the drive folder (rig.json, images/<camera>/...), on a file system every node sees
#   SHARED  a new or empty folder on such a file system: segments.tsv, segments/<k>/ (each
#           segment's reconstruction), city/ (the merged map), logs/, timing/, jobs.env
#   --segments K       segments (default 4)
#   --overlap F        frames each segment shares with the next (default 60)
#   --cpus-per-task C  CPUs of each task (default 2: the SfM and the surface threads)
#   --mem-per-task M   memory of each task, as sbatch's --mem (default: the partition's)
#   --omnisculpt PATH  the executable (default build/omnisculpt of this repository, else the one
#                      on PATH); the nodes run it at that path
#   --partition P, --time T (each task), --merge-time T (the merge job): passed to sbatch
#   --profile P        each segment's `reconstruct --profile` (default realtime; accurate: twice
#                      the corners, about 1.7 times the time; offline: about 6.5 times)
# Segment k is frames [a_k, b_k) of the drive's N frames (images/<first camera of rig.json>/):
# a_k = floor(k (N - F) / K), b_k = floor((k + 1) (N - F) / K) + F (b_(K-1) = N), so each shares F
# frames with the next and only with its neighbours (F must not exceed the stride (N - F) / K).
# Prints the job ids and where the results will be; SHARED/jobs.env holds them too.
# Errors: one line on stderr, exit 2 (bad drive or options, sbatch missing or refusing a job).
set -euo pipefail
me="submit.sh"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
die() { echo "$me: error: $*" >&2; exit 2; }

positional=()
segments=4
overlap=60
cpus=2
mem=""
omnisculpt=""
partition=""
time_limit=""
merge_time=""
profile="realtime"
while [ $# -gt 0 ]; do
  case "$1" in
    --segments | --overlap | --cpus-per-task | --mem-per-task | --omnisculpt | --partition | --time | --merge-time | --profile)
      [ $# -ge 2 ] || die "$1: expected a value"
      case "$1" in
        --segments) segments="$2" ;;
        --overlap) overlap="$2" ;;
        --cpus-per-task) cpus="$2" ;;
        --mem-per-task) mem="$2" ;;
        --omnisculpt) omnisculpt="$2" ;;
        --partition) partition="$2" ;;
        --time) time_limit="$2" ;;
        --merge-time) merge_time="$2" ;;
        --profile) profile="$2" ;;
      esac
      shift 2
      ;;
    -h | --help)
      sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed -e '$d' -e 's/^# \{0,1\}//'
      exit 0
      ;;
    -*) die "unknown option '$1' (--help lists them)" ;;
    *)
      positional+=("$1")
      shift
      ;;
  esac
done
[ ${#positional[@]} -eq 2 ] || die "expected DRIVE and SHARED (usage: $me DRIVE SHARED [options]; --help)"
drive="${positional[0]}"
shared="${positional[1]}"

is_count() { [[ "$1" =~ ^[0-9]+$ ]]; }
is_count "$segments" && [ "$segments" -ge 1 ] || die "--segments: expected a whole number of at least 1, got '$segments'"
is_count "$overlap" || die "--overlap: expected a whole number of frames, got '$overlap'"
is_count "$cpus" && [ "$cpus" -ge 1 ] || die "--cpus-per-task: expected a whole number of at least 1, got '$cpus'"
case "$profile" in
  realtime | accurate | offline) ;;
  *) die "--profile: expected realtime, accurate or offline, got '$profile'" ;;
esac

# The drive: rig.json's first camera and its image folder.
[ -d "$drive" ] || die "$drive: no such drive folder"
drive="$(cd "$drive" && pwd)"
[ -f "$drive/rig.json" ] || die "$drive/rig.json: missing (not a drive folder)"
first_camera="$(python3 -c '
import json, sys
try:
    rig = json.load(open(sys.argv[1]))
    print(rig["cameras"][0]["name"])
except Exception as error:
    sys.exit("%s" % error)
' "$drive/rig.json" 2>&1)" || die "$drive/rig.json: cannot read the first camera's name: $first_camera"
camera_folder="$drive/images/$first_camera"
[ -d "$camera_folder" ] || die "$camera_folder: missing (the first camera of rig.json has no image folder)"
frames="$(find "$camera_folder" -maxdepth 1 -type f \( -iname '*.png' -o -iname '*.jpg' -o -iname '*.jpeg' \) | wc -l)"
[ "$frames" -gt 0 ] || die "$camera_folder: no images"

# Segment k: [a_k, b_k), a_k = floor(k (N - F) / K), b_k = floor((k + 1) (N - F) / K) + F.
[ "$overlap" -lt "$frames" ] || die "--overlap $overlap: the drive has only $frames frames"
stride_frames=$(((frames - overlap) / segments))
[ "$stride_frames" -ge 1 ] || die "--segments $segments: too many for $frames frames overlapping by $overlap"
if [ "$segments" -gt 1 ]; then
  [ "$overlap" -ge 1 ] || die "--overlap 0: neighbouring segments must share frames for the merge to align them"
  [ "$overlap" -le "$stride_frames" ] ||
    die "--overlap $overlap: too large for $segments segments of $frames frames (at most $stride_frames, the stride; each segment would be $((stride_frames + overlap)) frames and overlap more than its neighbours)"
fi

# The executable, as an absolute path the nodes can run.
if [ -z "$omnisculpt" ]; then
  if [ -x "$here/../../build/omnisculpt" ]; then
    omnisculpt="$here/../../build/omnisculpt"
  else
    omnisculpt="$(command -v omnisculpt || true)"
    [ -n "$omnisculpt" ] || die "no omnisculpt executable: build it (scripts/setup.sh) or pass --omnisculpt PATH"
  fi
fi
[ -x "$omnisculpt" ] && [ -f "$omnisculpt" ] || die "--omnisculpt $omnisculpt: not an executable file"
omnisculpt="$(cd "$(dirname "$omnisculpt")" && pwd)/$(basename "$omnisculpt")"

command -v sbatch >/dev/null 2>&1 || die "sbatch not found: this machine is not a Slurm client (install slurm-client, or run on the cluster's login node)"

# SHARED: new or empty; what this script made there is removed again when sbatch refuses a job.
shared_was_there=0
if [ -e "$shared" ]; then
  [ -d "$shared" ] || die "$shared: exists and is not a folder"
  [ -z "$(ls -A "$shared")" ] || die "$shared: not empty (give a new or empty folder)"
  shared_was_there=1
fi
mkdir -p "$shared/segments" "$shared/logs" "$shared/timing" || die "$shared: cannot make the folder"
shared="$(cd "$shared" && pwd)"
undo_shared() {
  rm -f "$shared/segments.tsv" "$shared/logs/"segment_*.out "$shared/logs/merge.out"
  rmdir "$shared/segments" "$shared/logs" "$shared/timing" 2>/dev/null || true
  [ "$shared_was_there" = 1 ] || rmdir "$shared" 2>/dev/null || true
}

{
  printf 'segment\tfirst_frame\tend_frame\n'
  for ((k = 0; k < segments; k++)); do
    a=$((k * (frames - overlap) / segments))
    b=$(((k + 1) * (frames - overlap) / segments + overlap))
    [ "$k" -lt $((segments - 1)) ] || b="$frames"
    printf '%d\t%d\t%d\n' "$k" "$a" "$b"
  done
} >"$shared/segments.tsv"

common=()
[ -z "$partition" ] || common+=(--partition="$partition")
segment_options=(--cpus-per-task="$cpus")
[ -z "$mem" ] || segment_options+=(--mem="$mem")
[ -z "$time_limit" ] || segment_options+=(--time="$time_limit")
merge_options=(--cpus-per-task="$cpus")
[ -z "$mem" ] || merge_options+=(--mem="$mem")
[ -z "$merge_time" ] || merge_options+=(--time="$merge_time")

submitted="$(date +%s.%N)"
array_out="$(sbatch --parsable --array="0-$((segments - 1))" --job-name=omni-segment \
  --chdir="$shared" --output="$shared/logs/segment_%a.out" "${common[@]}" "${segment_options[@]}" \
  "$here/segment_job.sh" "$omnisculpt" "$drive" "$shared" "$profile" 2>&1)" || {
  undo_shared
  die "sbatch refused the segments' array job: $(echo "$array_out" | tr '\n' ' ')"
}
array_job="${array_out%%;*}"
[[ "$array_job" =~ ^[0-9]+$ ]] || die "sbatch printed no job id for the array: $array_out"
merge_out="$(sbatch --parsable --dependency="afterany:$array_job" --job-name=omni-merge \
  --chdir="$shared" --output="$shared/logs/merge.out" "${common[@]}" "${merge_options[@]}" \
  "$here/merge_job.sh" "$omnisculpt" "$shared" 2>&1)" || {
  scancel "$array_job" 2>/dev/null || true
  undo_shared
  die "sbatch refused the merge job (the array job $array_job is cancelled): $(echo "$merge_out" | tr '\n' ' ')"
}
merge_job="${merge_out%%;*}"
printf 'ARRAY_JOB=%s\nMERGE_JOB=%s\nSEGMENTS=%s\nSUBMITTED=%s\n' "$array_job" "$merge_job" "$segments" "$submitted" \
  >"$shared/jobs.env"

echo "$me: $drive: $frames frames in $segments segments overlapping by $overlap frames, $cpus CPUs per task, profile $profile"
while IFS=$'\t' read -r k a b; do
  echo "  segment $k: frames $a:$b -> $shared/segments/$k"
done < <(tail -n +2 "$shared/segments.tsv")
echo "array job $array_job (tasks 0-$((segments - 1))); merge job $merge_job (after the array: afterany)"
echo "city: $shared/city (merge.json names the segments that are missing); logs: $shared/logs/"
