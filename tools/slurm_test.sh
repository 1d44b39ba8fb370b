#!/usr/bin/env bash
# Runs the Slurm recipe of docs/guide.md on a one-node Slurm that this script starts and stops, and checks
# that the result equals a single-machine run byte for byte.
#
#   tools/slurm_test.sh [LIDARSIM [CAMPAIGN]]
#
# LIDARSIM is the binary (default $LIDARSIM, else target/release/lidarsim); CAMPAIGN defaults to
# a generated 4000-pulse track over a plane (4 parts). In a temporary folder it starts munged
# (its own key and socket) and slurmctld and slurmd (their own slurm.conf, on free ports), runs
# the campaign once on this machine (`--out single`), then submits it the way docs/guide.md gives: a job
# array of SHARDS tasks (default 3), task K running `--shard K/SHARDS`, and a `--resume` job
# with `--dependency=afterok:` on the array, both into `cluster`. It compares the two folders
# with tools/compare_runs.sh. Every daemon it started is stopped and the folder removed on any
# exit (SLURM_TEST_KEEP=1 keeps the folder). Needs root (slurmd runs jobs as their user).
# Exit 0: identical; 1: failure (the logs are printed); 2: Slurm or munge not installed, or not
# root (one line on stderr).
set -euo pipefail
export PATH="$PATH:/usr/sbin:/sbin"
repo=$(cd "$(dirname "$0")/.." && pwd)
lidarsim=${1:-${LIDARSIM:-$repo/target/release/lidarsim}}
campaign_arg=${2:-}
shards=${SHARDS:-3}
threads=${THREADS:-1}
timeout_s=${SLURM_TEST_TIMEOUT:-600}

missing=()
for tool in slurmctld slurmd sbatch squeue sinfo scontrol scancel munged; do
  command -v "$tool" >/dev/null 2>&1 || missing+=("$tool")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "slurm test: not run: ${missing[*]} not installed (apt-get install slurm-wlm munge)" >&2
  exit 2
fi
if [ "$(id -u)" -ne 0 ]; then
  echo "slurm test: not run: it must run as root (slurmd starts jobs as their user)" >&2
  exit 2
fi
[ -x "$lidarsim" ] || { echo "slurm test: no executable lidarsim at $lidarsim" >&2; exit 1; }
lidarsim=$(cd "$(dirname "$lidarsim")" && pwd)/$(basename "$lidarsim")
if [ -n "$campaign_arg" ]; then
  [ -f "$campaign_arg" ] || { echo "slurm test: no campaign file $campaign_arg" >&2; exit 1; }
  campaign_arg=$(cd "$(dirname "$campaign_arg")" && pwd)/$(basename "$campaign_arg")
fi

t0=$(date +%s)
tmp=$(mktemp -d "${TMPDIR:-/tmp}/slurm-test.XXXXXX")
# munged requires the folders above its socket to be searchable by all, and writable by root only
chmod 755 "$tmp"
pids=()      # daemons this script started, stopped in reverse order
jobs_ids=()  # jobs this script submitted, cancelled before the daemons stop
failed=1

show_logs() {
  local f
  for f in "$tmp"/munge/munged.{out,log} "$tmp"/slurm/slurmctld.{out,log} "$tmp"/slurm/slurmd.{out,log} \
    "$tmp"/jobs/*.out; do
    [ -s "$f" ] || continue
    echo "----- ${f#"$tmp"/} (last 40 lines) -----"
    tail -n 40 "$f"
  done
}

cleanup() {
  local code=$? pid i
  set +e
  if [ ${#jobs_ids[@]} -gt 0 ] && [ -n "${SLURM_CONF:-}" ]; then
    scancel "${jobs_ids[@]}" >/dev/null 2>&1
    for _ in $(seq 20); do
      [ -z "$(squeue -h -j "$(IFS=,; echo "${jobs_ids[*]}")" 2>/dev/null)" ] && break
      sleep 0.5
    done
  fi
  if [ "$failed" -ne 0 ]; then show_logs >&2; fi
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do
    pid=${pids[i]}
    kill -TERM "$pid" 2>/dev/null || continue
    for _ in $(seq 40); do kill -0 "$pid" 2>/dev/null || break; sleep 0.25; done
    kill -KILL "$pid" 2>/dev/null
    wait "$pid" 2>/dev/null
  done
  if [ "${SLURM_TEST_KEEP:-0}" = 1 ]; then
    echo "slurm test: kept $tmp" >&2
  else
    rm -rf "$tmp"
  fi
  exit "$code"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

die() {
  echo "slurm test: FAILED: $*" >&2
  exit 1
}

# A TCP port on which nothing listens, so that a second instance (or one left over from an
# earlier run) is not disturbed and does not disturb this one.
free_port() {
  local p
  for _ in $(seq 100); do
    p=$((20000 + RANDOM % 30000))
    if ! (exec 3<>"/dev/tcp/127.0.0.1/$p") 2>/dev/null; then
      echo "$p"
      return
    fi
  done
  die "no free TCP port found"
}

# ---- munge: its own key, socket, pid, log and seed files ----
mkdir -m 755 "$tmp/munge"
dd if=/dev/urandom of="$tmp/munge/munge.key" bs=1 count=1024 status=none
chmod 400 "$tmp/munge/munge.key"
socket=$tmp/munge/munge.socket
# -F: stays in the foreground (logging to stderr) so that $! is its pid
munged -F --key-file="$tmp/munge/munge.key" --socket="$socket" \
  --pid-file="$tmp/munge/munged.pid" --log-file="$tmp/munge/munged.log" \
  --seed-file="$tmp/munge/munged.seed" >"$tmp/munge/munged.out" 2>&1 &
pids+=($!)
for _ in $(seq 50); do [ -S "$socket" ] && break; sleep 0.1; done
if [ ! -S "$socket" ]; then cat "$tmp/munge/munged.out" >&2; die "munged did not start"; fi
if command -v munge >/dev/null && command -v unmunge >/dev/null; then
  munge -n -S "$socket" | unmunge -S "$socket" >/dev/null || die "munge cannot decode its own credential"
fi

# ---- slurm: one node, this machine ----
host=$(hostname -s)
cpus=$(nproc)
mem=$(awk '/^MemTotal:/ { print int($2 / 1024 * 0.9) }' /proc/meminfo)
ctld_port=$(free_port)
slurmd_port=$(free_port)
while [ "$slurmd_port" = "$ctld_port" ]; do slurmd_port=$(free_port); done
s=$tmp/slurm
mkdir -p "$s/state" "$s/spool" "$tmp/jobs"
cat >"$s/slurm.conf" <<EOF
ClusterName=lidarsimtest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$socket
StateSaveLocation=$s/state
SlurmdSpoolDir=$s/spool
SlurmctldPidFile=$s/slurmctld.pid
SlurmdPidFile=$s/slurmd.pid
SlurmctldLogFile=$s/slurmctld.log
SlurmdLogFile=$s/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
ReturnToService=2
MinJobAge=600
MailProg=/bin/true
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=test Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF=$s/slurm.conf
slurmctld -D -f "$SLURM_CONF" >"$s/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D -N "$host" -f "$SLURM_CONF" >"$s/slurmd.out" 2>&1 &
pids+=($!)

# ---- campaign ----
if [ -n "$campaign_arg" ]; then
  campaign=$campaign_arg
else
  cat >"$tmp/plane.yaml" <<'EOF'
name: p
materials:
  soil: { reflectance: { 1064: 0.3 } }
objects:
  - plane: { z: 0, extent: [[0, 0], [100, 100]], material: soil }
EOF
  campaign=$tmp/campaign.yaml
  cat >"$campaign" <<EOF
name: track
scene: $tmp/plane.yaml
seed: 9
wavelength_nm: 1064
instrument: { pulse_energy_j: 0.001, pulse_fwhm_ns: 2, footprint_half_angle_mrad: 0.5, fov_half_angle_mrad: 0.6, receiver_area_m2: 0.1 }
platform: { kind: track, altitude_m: 300, track: { start: [10, 50], end: [90, 50] }, along_track_step_m: 0.02 }
simulation: { method: bdpt, rays_per_pulse: 200, max_order: 5 }
EOF
fi

# the reference, on this machine, while slurmd registers
"$lidarsim" run "$campaign" --out "$tmp/single" --threads "$threads" >"$tmp/single.log" 2>&1 ||
  { cat "$tmp/single.log" >&2; die "the single-machine run failed"; }

state=
for _ in $(seq 120); do
  state=$(sinfo -h -n "$host" -o %t 2>/dev/null || true)
  [ "$state" = idle ] && break
  for pid in "${pids[@]}"; do kill -0 "$pid" 2>/dev/null || die "a daemon exited (pid $pid)"; done
  sleep 0.5
done
[ "$state" = idle ] || die "node $host is not idle after 60 s (sinfo says '${state:-nothing}')"

# ---- the recipe of docs/guide.md ----
cd "$tmp"
out=$tmp/cluster
array=$(sbatch --parsable --job-name=shards --array="0-$((shards - 1))" --cpus-per-task="$threads" \
  --output="$tmp/jobs/shard-%a.out" --wrap \
  "'$lidarsim' run '$campaign' --out '$out' --shard \$SLURM_ARRAY_TASK_ID/$shards --threads $threads")
array=${array%%;*}
jobs_ids+=("$array")
resume=$(sbatch --parsable --job-name=resume --dependency="afterok:$array" --kill-on-invalid-dep=yes \
  --cpus-per-task="$threads" --output="$tmp/jobs/resume.out" --wrap \
  "'$lidarsim' run '$campaign' --out '$out' --resume --threads $threads")
resume=${resume%%;*}
jobs_ids+=("$resume")
echo "slurm test: submitted array job $array ($shards tasks, --shard K/$shards) and resume job $resume (afterok:$array)"

# one line per job record: "<id> <state> <run time>"; an array's tasks are records of their own
records() {
  scontrol -o show job "$1" 2>/dev/null | awk '{
    id = ""; task = ""; st = ""; rt = ""
    for (i = 1; i <= NF; i++) {
      if ($i ~ /^JobId=/) id = substr($i, 7)
      else if ($i ~ /^ArrayJobId=/) id = substr($i, 12)
      else if ($i ~ /^ArrayTaskId=/) task = "_" substr($i, 13)
      else if ($i ~ /^JobState=/) st = substr($i, 10)
      else if ($i ~ /^RunTime=/) rt = substr($i, 9)
    }
    print id task, st, rt
  }'
}
terminal='^(COMPLETED|FAILED|CANCELLED|TIMEOUT|NODE_FAIL|OUT_OF_MEMORY|BOOT_FAIL|DEADLINE|PREEMPTED)$'
waited=0
while :; do
  all=$( { records "$array"; records "$resume"; } )
  pending=$(awk -v t="$terminal" '$2 !~ t' <<<"$all")
  # (scontrol may answer nothing for a moment: that is not "finished")
  [ -z "$pending" ] && grep -q "^$resume " <<<"$all" && grep -q "^${array}_" <<<"$all" && break
  [ "$waited" -ge "$timeout_s" ] && { echo "$all" >&2; die "jobs not finished after $timeout_s s"; }
  sleep 1
  waited=$((waited + 1))
done
echo "$all" | sort | awk '{ printf "  job %-10s %-10s %s\n", $1, $2, $3 }'
tasks=$(awk -v a="$array" 'index($1, a "_") == 1' <<<"$all" | wc -l)
[ "$tasks" -eq "$shards" ] || die "array job $array has $tasks task records, not $shards"
bad=$(awk '$2 != "COMPLETED"' <<<"$all")
[ -z "$bad" ] || die "jobs not COMPLETED: $(tr '\n' ';' <<<"$bad")"

cmp_out=$(bash "$repo/tools/compare_runs.sh" "$tmp/single" "$out") || { echo "$cmp_out" >&2; die "the Slurm run differs from the single-machine run"; }
echo "$cmp_out"
files=$(sed -nE 's/^([0-9]+) files identical.*/\1/p' <<<"$cmp_out")
failed=0
echo "slurm test: passed: array job $array ($shards tasks), resume job $resume, $(($(date +%s) - t0)) s, $files files identical"
