#!/usr/bin/env bash
# Reader throughput and memory: reads every point of LAS (mmap) and LAZ files of growing size
# and prints points/second and peak RSS. Peak RSS must not grow with the file size.
#   scripts/read-bench.sh [WORKDIR]      (default: a temporary directory, removed afterwards)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=target/release/crease
work=${1:-$(mktemp -d)}
[ -n "${1:-}" ] || trap 'rm -rf "$work"' EXIT
mkdir -p "$work"

for n in 2000000 20000000; do
  [ -f "$work/scene_$n.las" ] || $bin synth scene -n $n -o "$work/scene_$n.las" 2>/dev/null
  [ -f "$work/scene_$n.laz" ] || $bin synth scene -n $n -o "$work/scene_$n.laz" 2>/dev/null
done
printf '%-28s %12s %10s %14s %12s\n' file points seconds "M points/s" "peak RSS MB"
row() {
  local f=$1; shift
  "$@" $bin scan --json "$f" > "$work/scan.json"
  python3 - "$f" "$work/scan.json" <<'PY'
import json, sys, os
r = json.load(open(sys.argv[2]))
print(f"{os.path.basename(sys.argv[1]):<28} {r['records']:>12} {r['seconds']:>10.3f} {r['points_per_second']/1e6:>14.1f} {r['peak_rss_bytes']/1e6:>12.1f}")
PY
}
for n in 2000000 20000000; do
  # One core for the uncompressed reader (the target is per core); LAZ uses both.
  row "$work/scene_$n.las" taskset -c 0
  row "$work/scene_$n.laz"
done
shared=../shared/data/real
if [ -d "$shared" ]; then
  for f in lone-star.laz las_with_several_extra_byte_bloc.laz autzen_trim.las; do
    row "$shared/$f"
  done
fi
