#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, for the cluster test (tests/slurm/) and for trying
# scripts/slurm/submit.sh without a cluster. Every file is in DIR: slurm.conf (from
# scripts/slurm/local/slurm.conf.in), the MUNGE key and socket, the daemons' state, spool, pid
# and log files. No systemd, no cgroups; runs as root in a container (CI; as another user the
# daemons run as that user, which has not been tried).
#
# Usage: scripts/slurm/local_cluster.sh start DIR   # munged, slurmctld, slurmd; waits for the node
#        scripts/slurm/local_cluster.sh stop DIR    # cancels the jobs, stops exactly those daemons
#        scripts/slurm/local_cluster.sh status DIR  # sinfo of that cluster (exit 1 when down)
# Then: source DIR/env.sh (SLURM_CONF=DIR/slurm.conf) and use sbatch, squeue, sinfo, scontrol.
# Environment (start): OMNI_SLURM_CTLD_PORT, OMNI_SLURM_SLURMD_PORT (default 26817, 26818; a port
# in use is replaced by a free one), OMNI_SLURM_CPUS (default nproc), OMNI_SLURM_MEMORY_MB
# (default the machine's memory less 10 % and at least 512 MB), OMNI_SLURM_PARTITION (default
# omni), OMNI_SLURM_START_TIMEOUT (seconds, default 60).
# Exit codes: 0 done; 1 a daemon did not come up (the error names its log) or did not stop;
# 2 bad usage, or Slurm / MUNGE not installed (scripts/setup.sh --with-test-packages).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
me="local_cluster.sh"

die() { echo "$me: error: $*" >&2; exit "${2:-1}"; }
usage() { die "usage: $me start|stop|status DIR" 2; }

[ $# -eq 2 ] || usage
action="$1"
case "$2" in /*) dir="$2" ;; *) dir="$(pwd)/$2" ;; esac
case "$action" in start | stop | status) ;; *) usage ;; esac

# Finds the daemons' executables; Debian puts munged, slurmctld and slurmd in /usr/sbin, which is
# not on every user's PATH.
find_program() {
  local name="$1" path
  path="$(command -v "$name" 2>/dev/null || true)"
  if [ -z "$path" ]; then
    for candidate in "/usr/sbin/$name" "/sbin/$name" "/usr/local/sbin/$name"; do
      if [ -x "$candidate" ]; then path="$candidate"; break; fi
    done
  fi
  echo "$path"
}

require_programs() {
  local missing=() name
  for name in munged slurmctld slurmd sinfo scontrol squeue scancel sbatch; do
    [ -n "$(find_program "$name")" ] || missing+=("$name")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    die "${missing[*]} not found: install slurm-wlm and munge (scripts/setup.sh --with-test-packages)" 2
  fi
}

# The pid in a pid file, when that process is alive.
live_pid() {
  local file="$1" pid
  [ -f "$file" ] || return 1
  pid="$(tr -dc '0-9' <"$file")"
  [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null && echo "$pid"
}

port_free() {
  python3 - "$1" <<'PY'
import socket, sys
s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
# As the daemons bind (SO_REUSEADDR): a port of a cluster that just stopped is free.
s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
try:
    s.bind(("127.0.0.1", int(sys.argv[1])))
except OSError:
    sys.exit(1)
PY
}

free_port() {
  python3 - <<'PY'
import socket
s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
s.bind(("127.0.0.1", 0))
print(s.getsockname()[1])
PY
}

# The last lines of a daemon's log, for an error message.
log_tail() {
  [ -f "$1" ] && tail -n 15 "$1" | sed 's/^/    /' >&2 || true
}

wait_for_node() {
  local timeout="$1" start=$SECONDS state=""
  while [ $((SECONDS - start)) -lt "$timeout" ]; do
    [ -n "$(live_pid "$dir/run/slurmctld.pid" || true)" ] || {
      log_tail "$dir/log/slurmctld.log"
      die "slurmctld exited while starting: see $dir/log/slurmctld.log"
    }
    [ -n "$(live_pid "$dir/run/slurmd.pid" || true)" ] || {
      log_tail "$dir/log/slurmd.log"
      die "slurmd exited while starting: see $dir/log/slurmd.log"
    }
    state="$(SLURM_CONF="$dir/slurm.conf" sinfo -h -N -o '%t' 2>/dev/null | head -n 1 || true)"
    case "$state" in idle | mix | alloc) return 0 ;; esac
    sleep 0.5
  done
  log_tail "$dir/log/slurmctld.log"
  log_tail "$dir/log/slurmd.log"
  die "the node is not idle after ${timeout} s (sinfo state '${state:-none}'): see $dir/log/slurmctld.log and $dir/log/slurmd.log"
}

start() {
  require_programs
  if [ -n "$(live_pid "$dir/run/slurmctld.pid" || true)" ] || [ -n "$(live_pid "$dir/run/munged.pid" || true)" ]; then
    die "$dir: a cluster is already running there ($me stop $dir first)" 2
  fi
  mkdir -p "$dir"
  chmod 700 "$dir"
  mkdir -p "$dir/munge" "$dir/state" "$dir/spool" "$dir/run" "$dir/log"
  chmod 700 "$dir/munge"
  local start_seconds=$SECONDS
  local host cpus memory_mb mem_per_cpu ctld_port slurmd_port user partition timeout
  host="$(hostname -s)"
  cpus="${OMNI_SLURM_CPUS:-$(nproc)}"
  memory_mb="${OMNI_SLURM_MEMORY_MB:-$(awk '/^MemTotal:/ { m = int($2 / 1024 * 0.9); if (m < 512) m = 512; print m }' /proc/meminfo)}"
  mem_per_cpu=$((memory_mb / cpus))
  partition="${OMNI_SLURM_PARTITION:-omni}"
  timeout="${OMNI_SLURM_START_TIMEOUT:-60}"
  user="$(id -un)"
  ctld_port="${OMNI_SLURM_CTLD_PORT:-26817}"
  slurmd_port="${OMNI_SLURM_SLURMD_PORT:-26818}"
  port_free "$ctld_port" || ctld_port="$(free_port)"
  while ! port_free "$slurmd_port" || [ "$slurmd_port" = "$ctld_port" ]; do slurmd_port="$(free_port)"; done

  sed -e "s|@DIR@|$dir|g" -e "s|@HOST@|$host|g" -e "s|@USER@|$user|g" \
    -e "s|@CTLD_PORT@|$ctld_port|g" -e "s|@SLURMD_PORT@|$slurmd_port|g" \
    -e "s|@CPUS@|$cpus|g" -e "s|@MEMORY_MB@|$memory_mb|g" -e "s|@MEM_PER_CPU_MB@|$mem_per_cpu|g" \
    -e "s|@PARTITION@|$partition|g" "$here/local/slurm.conf.in" >"$dir/slurm.conf.tmp"
  mv "$dir/slurm.conf.tmp" "$dir/slurm.conf"
  printf 'export SLURM_CONF=%q\n' "$dir/slurm.conf" >"$dir/env.sh"

  # MUNGE: a new key, its own socket, pid, seed and log; --force because munged refuses to run
  # as root (and a socket folder outside /run) otherwise.
  rm -f "$dir/munge/munge.key"
  if command -v mungekey >/dev/null 2>&1 || [ -x /usr/sbin/mungekey ]; then
    "$(find_program mungekey)" --create --keyfile="$dir/munge/munge.key" >/dev/null 2>&1 ||
      dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none
  else
    dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none
  fi
  chmod 600 "$dir/munge/munge.key"
  "$(find_program munged)" --force --socket="$dir/munge/munge.socket" \
    --key-file="$dir/munge/munge.key" --pid-file="$dir/run/munged.pid" \
    --seed-file="$dir/munge/munged.seed" --log-file="$dir/log/munged.log" \
    >>"$dir/log/munged.out" 2>&1 || {
    log_tail "$dir/log/munged.log"
    log_tail "$dir/log/munged.out"
    die "munged did not start: see $dir/log/munged.log"
  }
  local waited=0
  until [ -S "$dir/munge/munge.socket" ]; do
    [ $waited -lt 100 ] || die "munged made no socket in 10 s: see $dir/log/munged.log"
    sleep 0.1
    waited=$((waited + 1))
  done

  # The daemons fork into the background and write their pid files; -f names the config.
  "$(find_program slurmctld)" -f "$dir/slurm.conf" >>"$dir/log/slurmctld.out" 2>&1 || {
    log_tail "$dir/log/slurmctld.log"
    log_tail "$dir/log/slurmctld.out"
    die "slurmctld did not start: see $dir/log/slurmctld.log"
  }
  "$(find_program slurmd)" -f "$dir/slurm.conf" -N "$host" >>"$dir/log/slurmd.out" 2>&1 || {
    log_tail "$dir/log/slurmd.log"
    log_tail "$dir/log/slurmd.out"
    die "slurmd did not start: see $dir/log/slurmd.log"
  }
  # The pid files appear once the daemons have forked.
  waited=0
  until [ -s "$dir/run/slurmctld.pid" ] && [ -s "$dir/run/slurmd.pid" ]; do
    if [ $waited -ge 100 ]; then
      [ -s "$dir/run/slurmctld.pid" ] || die "slurmctld wrote no pid file in 10 s: see $dir/log/slurmctld.log"
      die "slurmd wrote no pid file in 10 s: see $dir/log/slurmd.log"
    fi
    sleep 0.1
    waited=$((waited + 1))
  done
  wait_for_node "$timeout"
  echo "$me: cluster up in $((SECONDS - start_seconds)) s: node $host, $cpus CPUs, ${memory_mb} MB, partition $partition, ports $ctld_port/$slurmd_port; SLURM_CONF=$dir/slurm.conf (source $dir/env.sh)"
}

# Sends TERM to the daemon of a pid file, waits up to 20 s, then KILL.
stop_daemon() {
  local name="$1" file="$2" pid waited=0
  pid="$(live_pid "$file" || true)"
  [ -n "$pid" ] || { rm -f "$file"; return 0; }
  kill -TERM "$pid" 2>/dev/null || true
  while kill -0 "$pid" 2>/dev/null; do
    if [ $waited -ge 200 ]; then
      echo "$me: $name (pid $pid) did not stop in 20 s: killing it" >&2
      kill -KILL "$pid" 2>/dev/null || true
      sleep 0.5
      kill -0 "$pid" 2>/dev/null && die "$name (pid $pid) is still running"
      break
    fi
    sleep 0.1
    waited=$((waited + 1))
  done
  rm -f "$file"
}

stop() {
  [ -d "$dir" ] || { echo "$me: $dir: no cluster folder, nothing to stop"; return 0; }
  # The jobs first (their processes are slurmd's children), while the controller still runs.
  if [ -n "$(live_pid "$dir/run/slurmctld.pid" || true)" ] && [ -f "$dir/slurm.conf" ]; then
    local scancel_path squeue_path waited=0
    scancel_path="$(find_program scancel)"
    squeue_path="$(find_program squeue)"
    if [ -n "$scancel_path" ] && [ -n "$squeue_path" ]; then
      SLURM_CONF="$dir/slurm.conf" "$scancel_path" --full --quiet --user="$(id -un)" 2>/dev/null || true
      while [ -n "$(SLURM_CONF="$dir/slurm.conf" "$squeue_path" -h -o '%i' 2>/dev/null || true)" ] && [ $waited -lt 300 ]; do
        sleep 0.1
        waited=$((waited + 1))
      done
    fi
  fi
  stop_daemon slurmd "$dir/run/slurmd.pid"
  stop_daemon slurmctld "$dir/run/slurmctld.pid"
  stop_daemon munged "$dir/run/munged.pid"
  echo "$me: cluster in $dir stopped"
}

status() {
  [ -f "$dir/slurm.conf" ] || die "$dir: no slurm.conf (not a cluster folder)" 2
  [ -n "$(live_pid "$dir/run/slurmctld.pid" || true)" ] || die "$dir: slurmctld is not running"
  SLURM_CONF="$dir/slurm.conf" sinfo -N
}

"$action"
