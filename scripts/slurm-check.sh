#!/usr/bin/env bash
# Runs an extraction as a Slurm job chain (`crease slurm --submit`) on a single-node Slurm
# started here, and compares its curves with those of one `crease extract`.
#   scripts/slurm-check.sh [WORKDIR] [POINTS] [TASKS]
# Needs root and Debian's packages (installed if missing): slurm-wlm, munge.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=$PWD/target/release/crease
work=$(realpath -m "${1:-/tmp/slurm-check}")
n=${2:-2000000}
tasks=${3:-3}
command -v slurmctld >/dev/null || apt-get install -y slurm-wlm munge >/dev/null
mkdir -p "$work" /etc/slurm /var/lib/slurm/slurmd /var/lib/slurm/slurmctld /var/log/slurm /run/munge
cpus=$(nproc)
mem=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 512 ))
cat > /etc/slurm/slurm.conf <<CONF
ClusterName=crease-check
SlurmctldHost=$(hostname -s)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
StateSaveLocation=/var/lib/slurm/slurmctld
SlurmdSpoolDir=/var/lib/slurm/slurmd
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
NodeName=$(hostname -s) CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=check Nodes=$(hostname -s) Default=YES MaxTime=INFINITE State=UP
CONF
[ -f /etc/munge/munge.key ] || mungekey --create >/dev/null 2>&1 || dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key 2>/dev/null
chown -R munge:munge /etc/munge /run/munge 2>/dev/null || true
chmod 400 /etc/munge/munge.key
pgrep -x munged >/dev/null || runuser -u munge -- munged
pgrep -x slurmctld >/dev/null || slurmctld
pgrep -x slurmd >/dev/null || slurmd
for _ in $(seq 30); do sinfo -h -o %T 2>/dev/null | grep -qE 'idle|mixed' && break; sleep 1; done
sinfo
cloud=$work/scene_$n.las
[ -f "$cloud" ] || "$bin" synth scene -n "$n" --noise 0.005 -o "$cloud" 2>/dev/null
rm -rf "$work/plain" "$work/chained"
t0=$(date +%s.%N)
"$bin" extract "$cloud" -o "$work/plain" -q
t1=$(date +%s.%N)
# (Small tiles, so that each worker has a share of several.)
"$bin" slurm "$cloud" -o "$work/chained" -q --tile-size 20 --tasks "$tasks" --submit -- --mem=3G
for _ in $(seq 1800); do
  [ -z "$(squeue -h -n crease-plan,crease-statistics,crease-residuals,crease-projection,crease-growing,crease-curves)" ] && break
  sleep 1
done
t2=$(date +%s.%N)
"$bin" status "$work/chained"
ls "$work/chained/slurm"
echo "crease extract: $(echo "$t1 - $t0" | bc) s; the chain of $tasks workers: $(echo "$t2 - $t1" | bc) s (2 cores)"
"$bin" extract "$cloud" -o "$work/plain_tiles" -q --tile-size 20 --force
if cmp -s "$work/plain/curves.obj" "$work/chained/curves.obj" && cmp -s "$work/plain_tiles/curves.obj" "$work/chained/curves.obj"; then
  echo "same curves.obj as crease extract (default tiles and the chain's tiles): $(grep -c '^l' "$work/chained/curves.obj") curves"
else
  echo "DIFFERENT curves"; exit 1
fi
