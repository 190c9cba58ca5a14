#!/usr/bin/env bash
# Out-of-core check: generates a large LAS scene (default 100 M points, about 2 GB) and runs
# `crease extract --memory 1G` on it, reporting peak RSS and seconds per pass; then, where the
# machine allows (root and cgroup v2), runs it again inside a cgroup limited to 1 GiB.
# Also scores the result against the scene's truth.
#   scripts/ooc-check.sh [WORKDIR] [POINTS]
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=$PWD/target/release/crease
work=${1:-$(mktemp -d)}
n=${2:-100000000}
mkdir -p "$work"
las=$work/scene_$n.las
if [ ! -f "$las" ]; then
  /usr/bin/time -v "$bin" synth scene -n "$n" -o "$las" 2> "$work/synth.time"
  grep -E "Elapsed|Maximum resident" "$work/synth.time"
fi
ls -l "$las"
run() { # name, then the command prefix
  local name=$1; shift
  # (A fresh directory: the same job in an existing one would resume, not be timed.)
  rm -rf "${work:?}/$name"
  /usr/bin/time -v "$@" "$bin" extract "$las" -o "$work/$name" --memory 1G 2> "$work/$name.time" || { tail -5 "$work/$name.time"; return 1; }
  grep -E "Elapsed|Maximum resident" "$work/$name.time"
  python3 - "$work/$name/report.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
print(f"{r['counts']['points']} points, {r['tiles']} tiles of {r['tile_size']:.1f} m, {r['total_seconds']:.0f} s "
      f"({r['counts']['points']/r['total_seconds']/1e6:.2f} M points/s), peak RSS {r['peak_rss_bytes']/1e6:.0f} MB")
print("pass seconds:", json.dumps(r["pass_seconds"]))
PY
  # Truth tolerance: 0.1 m (the scene is in metres; --diag 10 makes --tol 0.01 mean 10 cm).
  "$bin" eval --truth "${las%.las}.truth.obj" --curves "$work/$name/curves.obj" --diag 10
}
run plain
cg=/sys/fs/cgroup
limit=$((1024 * 1024 * 1024))
if [ "$(id -u)" = 0 ] && [ -f $cg/cgroup.controllers ] && grep -q memory $cg/cgroup.controllers; then
  # cgroup v2
  echo "+memory" > $cg/cgroup.subtree_control 2>/dev/null || true
  mkdir -p $cg/crease-ooc
  echo $limit > $cg/crease-ooc/memory.max
  echo 0 > $cg/crease-ooc/memory.swap.max 2>/dev/null || true
  echo "running inside cgroup v2 crease-ooc with memory.max = 1 GiB"
  run cgroup sh -c "echo \$\$ > $cg/crease-ooc/cgroup.procs && exec \"\$0\" \"\$@\""
  echo "cgroup memory.peak: $(cat $cg/crease-ooc/memory.peak 2>/dev/null || echo n/a)"
  echo "cgroup OOM kills: $(grep oom_kill $cg/crease-ooc/memory.events 2>/dev/null || echo n/a)"
elif [ "$(id -u)" = 0 ] && [ -d $cg/memory ]; then
  # cgroup v1
  mkdir -p $cg/memory/crease-ooc
  echo $limit > $cg/memory/crease-ooc/memory.limit_in_bytes
  echo $limit > $cg/memory/crease-ooc/memory.memsw.limit_in_bytes 2>/dev/null || true
  echo 0 > $cg/memory/crease-ooc/memory.max_usage_in_bytes 2>/dev/null || true
  echo "running inside cgroup v1 memory:crease-ooc with memory.limit_in_bytes = 1 GiB"
  run cgroup sh -c "echo \$\$ > $cg/memory/crease-ooc/cgroup.procs && exec \"\$0\" \"\$@\""
  echo "cgroup max usage (includes page cache): $(cat $cg/memory/crease-ooc/memory.max_usage_in_bytes)"
  echo "cgroup OOM events: $(grep -E 'oom_kill|under_oom' $cg/memory/crease-ooc/memory.oom_control | tr '\n' ' ')"
else
  echo "no cgroup memory controller available here (needs root and cgroup v1 or v2): cgroup run skipped"
fi
