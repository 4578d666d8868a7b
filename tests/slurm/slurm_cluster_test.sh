#!/usr/bin/env bash
# The cluster test: brings up a one-node Slurm cluster on this machine
# (scripts/slurm/local_cluster.sh), makes the demo drive (400 frames around a block), submits it
# in 4 overlapping segments through scripts/slurm/submit.sh, waits for the array and the merge,
# then compares the merged map with one `omnisculpt reconstruct` of the whole drive, both scored
# by `omnisculpt eval`:
#   * every segment and the merge succeeded, and merge.json names no missing segment and merged
#     every input (each joined to the others by a verified overlap);
#   * the city's keyframe ATE (eval.json poses.ate_translation_m.rmse) is at most 1.5 times the
#     single run's;
#   * the city's surface.ply is an oriented 2-manifold with boundary (mesh-check
#     --allow-boundary, and boundary loops);
#   * its pixel F-score at 0.5 m (eval.json pixel.precision_recall) is within 0.05 of the
#     single run's.
# It prints the wall times (bring-up, the segments from submission to the last one's end, the
# merge job, the single run, the evaluations) and both evaluations' figures side by side. The
# cluster is stopped whatever happens (trap); a cluster that cannot start fails the test.
#
# Usage: slurm_cluster_test.sh --omnisculpt PATH --scripts SCRIPTS_SLURM_DIR --work DIR
# For the figures only (not checked) it also evaluates one run of the whole drive with
# --no-loop-closure: the merge does not close a revisit between segments that share no frame.
# Environment: OMNI_SLURM_TEST_WAIT (seconds to wait for the jobs, default 2400),
#   OMNI_SLURM_TEST_CPUS_PER_TASK (default 2 on 8 cores or more, else 1: two tasks at once),
#   OMNI_SLURM_TEST_OVERLAP (frames each segment shares with the next, default 60).
set -uo pipefail
me="slurm_cluster_test"
fail() { echo "FAIL: $me: $*"; exit 1; }

omnisculpt="" scripts="" work=""
while [ $# -gt 0 ]; do
  case "$1" in
    --omnisculpt) omnisculpt="$2"; shift 2 ;;
    --scripts) scripts="$2"; shift 2 ;;
    --work) work="$2"; shift 2 ;;
    *) fail "unknown argument '$1'" ;;
  esac
done
[ -x "$omnisculpt" ] || fail "--omnisculpt '$omnisculpt': not an executable"
[ -f "$scripts/submit.sh" ] && [ -f "$scripts/local_cluster.sh" ] || fail "--scripts '$scripts': no submit.sh / local_cluster.sh"
[ -n "$work" ] || fail "--work: expected a folder"

segments=4
overlap="${OMNI_SLURM_TEST_OVERLAP:-60}"
wait_limit="${OMNI_SLURM_TEST_WAIT:-2400}"
cores="$(nproc)"
cpus_per_task="${OMNI_SLURM_TEST_CPUS_PER_TASK:-$([ "$cores" -ge 8 ] && echo 2 || echo 1)}"

# A cluster left running by an earlier run that was killed (ctest's timeout) is stopped first.
if [ -f "$work/cluster_dir" ]; then
  stale="$(cat "$work/cluster_dir")"
  if [ -d "$stale" ]; then
    bash "$scripts/local_cluster.sh" stop "$stale" || true
    rm -rf "$stale"
  fi
fi
rm -rf "$work"
mkdir -p "$work" || fail "$work: cannot make the folder"
work="$(cd "$work" && pwd)"
# The cluster's own folder: short (the MUNGE socket path must fit a Unix socket address) and
# private to this run.
cluster="$(mktemp -d "${TMPDIR:-/tmp}/omni-slurm-test.XXXXXX")" || fail "cannot make a temporary folder"
echo "$cluster" >"$work/cluster_dir"

cleanup() {
  local code=$?
  bash "$scripts/local_cluster.sh" stop "$cluster" || echo "$me: warning: the cluster in $cluster did not stop cleanly"
  mkdir -p "$work/cluster_logs"
  cp "$cluster"/log/* "$cluster/slurm.conf" "$work/cluster_logs/" 2>/dev/null || true
  rm -rf "$cluster" "$work/cluster_dir"
  exit "$code"
}
trap cleanup EXIT
trap 'exit 1' INT TERM HUP

now() { date +%s.%N; }
seconds_between() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", b - a }'; }

echo "$me: machine: $cores cores, load $(cut -d' ' -f1-3 /proc/loadavg)"
t="$(now)"
bash "$scripts/local_cluster.sh" start "$cluster" || fail "the local Slurm cluster did not start (logs above and in $work/cluster_logs/)"
bringup_s="$(seconds_between "$t" "$(now)")"
# shellcheck disable=SC1091
source "$cluster/env.sh"

drive="$work/demo_drive"
t="$(now)"
"$omnisculpt" --quiet synth --preset demo --out "$drive" || fail "synth --preset demo failed"
synth_s="$(seconds_between "$t" "$(now)")"

shared="$work/shared"
load_before_cluster="$(cut -d' ' -f1-3 /proc/loadavg)"
bash "$scripts/submit.sh" "$drive" "$shared" --segments "$segments" --overlap "$overlap" \
  --cpus-per-task "$cpus_per_task" --omnisculpt "$omnisculpt" --time 60 --merge-time 60 ||
  fail "submit.sh failed"
# shellcheck disable=SC1091
source "$shared/jobs.env"
[ -n "${ARRAY_JOB:-}" ] && [ -n "${MERGE_JOB:-}" ] || fail "$shared/jobs.env: no job ids"

# Waits until neither job is queued or running (squeue), with a time limit.
start_wait=$SECONDS
last_report=0
while true; do
  queued="$(squeue -h -j "$ARRAY_JOB,$MERGE_JOB" -o '%i %T' 2>/dev/null)"
  [ -n "$queued" ] || break
  if [ $((SECONDS - start_wait)) -ge "$wait_limit" ]; then
    echo "$queued"
    fail "the jobs did not finish in $wait_limit s (logs: $shared/logs/)"
  fi
  if [ $((SECONDS - last_report)) -ge 60 ]; then
    echo "$me: waiting ($((SECONDS - start_wait)) s): $(echo "$queued" | tr '\n' ' ')"
    last_report=$SECONDS
  fi
  sleep 1
done
load_after_cluster="$(cut -d' ' -f1-3 /proc/loadavg)"

# The jobs' states (scontrol keeps finished jobs for MinJobAge; there is no accounting for sacct).
job_states="$(scontrol show job -o "$ARRAY_JOB" 2>/dev/null; scontrol show job -o "$MERGE_JOB" 2>/dev/null)"
echo "$me: jobs:"
echo "$job_states" | awk 'NF {
  line = "   "
  for (i = 1; i <= NF; i++)
    if ($i ~ /^(JobId|ArrayTaskId|JobName|JobState|ExitCode|RunTime|StartTime|EndTime)=/) line = line " " $i
  print line
}'
for log in "$shared"/logs/*.out; do
  if grep -qi 'error' "$log"; then
    echo "$me: $log:"
    tail -n 20 "$log" | sed 's/^/    /'
  fi
done

# Wall times from the jobs' own timing files (start and end of each task, seconds since 1970).
segments_end=0
failed_segments=()
for ((k = 0; k < segments; k++)); do
  file="$shared/timing/segment_$k.tsv"
  if [ ! -f "$file" ]; then
    failed_segments+=("$k (did not run: $shared/logs/segment_$k.out)")
    continue
  fi
  read -r s e code _ < <(tail -n 1 "$file")
  echo "$me: segment $k: $(awk -F'\t' -v k="$k" '$1 == k { print "frames " $2 ":" $3 }' "$shared/segments.tsv"), $(seconds_between "$s" "$e") s, exit code $code"
  [ "$code" = 0 ] || failed_segments+=("$k (exit code $code: $shared/logs/segment_$k.out)")
  segments_end="$(awk -v a="$segments_end" -v b="$e" 'BEGIN { print (b > a) ? b : a }')"
done
cluster_segments_s="$(seconds_between "$SUBMITTED" "$segments_end")"
[ -f "$shared/timing/merge.tsv" ] || fail "the merge job did not run (log: $shared/logs/merge.out)"
read -r merge_start merge_end merge_code _ < <(tail -n 1 "$shared/timing/merge.tsv")
merge_s="$(seconds_between "$merge_start" "$merge_end")"
merge_wait_s="$(seconds_between "$segments_end" "$merge_start")"

# The single run of the whole drive, after the cluster's jobs (the machine is not shared).
single="$work/single"
load_before_single="$(cut -d' ' -f1-3 /proc/loadavg)"
t="$(now)"
"$omnisculpt" --quiet reconstruct "$drive" --out "$single" || fail "the single reconstruct of $drive failed"
single_s="$(seconds_between "$t" "$(now)")"

single_no_loop="$work/single_no_loop_closure"
t="$(now)"
"$omnisculpt" --quiet reconstruct "$drive" --no-loop-closure --out "$single_no_loop" ||
  fail "the single reconstruct --no-loop-closure of $drive failed"
single_no_loop_s="$(seconds_between "$t" "$(now)")"
"$omnisculpt" --quiet eval --gt "$drive" --rec "$single_no_loop" || fail "eval of the single run without loop closure failed"

city="$shared/city"
t="$(now)"
city_eval_ok=1
[ -f "$city/surface.ply" ] && "$omnisculpt" --quiet eval --gt "$drive" --rec "$city" || city_eval_ok=0
city_eval_s="$(seconds_between "$t" "$(now)")"
t="$(now)"
"$omnisculpt" --quiet eval --gt "$drive" --rec "$single" || fail "eval of the single run failed"
single_eval_s="$(seconds_between "$t" "$(now)")"

echo
echo "$me: wall times (s), $cores cores, $cpus_per_task CPUs per task, load before the jobs $load_before_cluster, after $load_after_cluster, before the single run $load_before_single"
printf '    %-52s %8s\n' "cluster bring-up (munged, slurmctld, slurmd, node idle)" "$bringup_s" \
  "synth --preset demo" "$synth_s" \
  "$segments segments, submission to the last segment's end" "$cluster_segments_s" \
  "merge job (last segment's end to its start: $merge_wait_s)" "$merge_s" \
  "segments + merge" "$(awk -v a="$cluster_segments_s" -v b="$merge_wait_s" -v c="$merge_s" 'BEGIN { printf "%.1f", a + b + c }')" \
  "single reconstruct of the $(ls "$drive/images/$(ls "$drive/images" | head -n 1)" | wc -l) frames" "$single_s" \
  "single reconstruct --no-loop-closure" "$single_no_loop_s" \
  "eval of the city / of the single run" "$city_eval_s / $single_eval_s"

# Both evaluations side by side, and the checks.
OMNI_EXECUTABLE="$omnisculpt" python3 - "$city" "$single" "$single_no_loop" "$merge_code" "${#failed_segments[@]}" "$city_eval_ok" <<'PY'
import json, os, subprocess, sys
city, single, single_no_loop, merge_code, failed_segments, city_eval_ok = sys.argv[1:7]
problems = []

def figures(rec):
    with open(os.path.join(rec, "report", "eval.json")) as f:
        e = json.load(f)
    p = e["poses"]
    f05 = [x for x in e["pixel"]["precision_recall"] if abs(x["threshold_m"] - 0.5) < 1e-9]
    f02 = [x for x in e["pixel"]["precision_recall"] if abs(x["threshold_m"] - 0.2) < 1e-9]
    m = e["estimated_mesh"]
    return {
        "keyframes matched": p["matched"],
        "ATE RMS (m)": p["ate_translation_m"]["rmse"],
        "ATE median (m)": p["ate_translation_m"]["median"],
        "ATE max (m)": p["ate_translation_m"]["max"],
        "registration RMS (m)": p["registration_rms_m"],
        "rotation RMS (deg)": p["ate_rotation_deg"]["rmse"],
        "pixel F at 0.2 m": f02[0]["f_score"] if f02 else float("nan"),
        "pixel F at 0.5 m": f05[0]["f_score"] if f05 else float("nan"),
        "ray error median (m)": e["ray_errors"]["errors_m"]["median"],
        "surface.ply triangles": m["triangles"],
        "surface.ply boundary loops": m["boundary_loops"],
        "surface.ply manifold (boundary allowed)": m["ok"],
    }

if merge_code != "0":
    problems.append("the merge job exited with %s" % merge_code)
if failed_segments != "0":
    problems.append("%s segment(s) failed" % failed_segments)
merge_json = os.path.join(city, "merge.json")
if os.path.isfile(merge_json):
    with open(merge_json) as f:
        merge = json.load(f)
    if merge.get("missing"):
        problems.append("merge.json: missing %s" % merge["missing"])
    left_out = [(i.get("folder"), i.get("why")) for i in merge.get("inputs", []) if not i.get("merged")]
    if left_out:
        problems.append("merge.json: segments not merged %s" % left_out)
else:
    problems.append("%s: missing" % merge_json)
for name in ["poses.tum", "frame_poses.tum", "points.ply", "surface.ply", "surface_closed.ply", "sparse", "stats"]:
    if not os.path.exists(os.path.join(city, name)):
        problems.append("%s: missing" % os.path.join(city, name))

s = figures(single)
n = figures(single_no_loop)
c = figures(city) if city_eval_ok == "1" else None
if c is None:
    problems.append("eval of the city failed")
print("\nslurm_cluster_test: %-40s %14s %14s %16s" % ("eval (omnisculpt eval --gt DRIVE)", "city (merged)",
                                                     "single run", "single, no loop"))
for key in s:
    def show(v):
        if v is None:
            return "-"
        return "%.4f" % v if isinstance(v, float) else str(v)
    print("    %-40s %14s %14s %16s" % (key, show(c[key] if c else None), show(s[key]), show(n[key])))

if c is not None:
    if not c["ATE RMS (m)"] <= 1.5 * s["ATE RMS (m)"]:
        problems.append("the city's ATE RMS %.4f m is above 1.5 x the single run's %.4f m"
                        % (c["ATE RMS (m)"], s["ATE RMS (m)"]))
    if not abs(c["pixel F at 0.5 m"] - s["pixel F at 0.5 m"]) <= 0.05:
        problems.append("the city's pixel F at 0.5 m %.3f is not within 0.05 of the single run's %.3f"
                        % (c["pixel F at 0.5 m"], s["pixel F at 0.5 m"]))
if os.path.isfile(os.path.join(city, "surface.ply")):
    omnisculpt = os.environ["OMNI_EXECUTABLE"]
    check = subprocess.run([omnisculpt, "mesh-check", "--allow-boundary", "--json",
                            os.path.join(city, "surface.ply")], capture_output=True, text=True)
    report = json.loads(check.stdout) if check.stdout.strip().startswith("{") else {}
    if check.returncode != 0 or not report.get("oriented") or report.get("nonmanifold_edges", 1) != 0:
        problems.append("the city's surface.ply is not an oriented 2-manifold (mesh-check exit %d)"
                        % check.returncode)
    elif report.get("boundary_loops", 0) < 1 or report.get("triangles", 0) < 1:
        problems.append("the city's surface.ply has no boundary or no triangles (%s loops, %s triangles)"
                        % (report.get("boundary_loops"), report.get("triangles")))
for p in problems:
    print("FAIL: slurm_cluster_test: " + p)
sys.exit(1 if problems else 0)
PY
checks=$?
[ "$checks" = 0 ] || exit 1
echo "$me: passed"
