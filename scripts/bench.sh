#!/usr/bin/env bash
# End-to-end speed on a 500 k-point CAD cloud (per-stage seconds from report.json), median of
# three runs, on all cores and on one.
#   scripts/bench.sh [WORKDIR] [SHAPE] [POINTS] [NOISE]
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=$PWD/target/release/crease
work=${1:-$(mktemp -d)}
shape=${2:-fandisk}
n=${3:-500000}
noise=${4:-0}
mkdir -p "$work"
cloud=$work/${shape}_${n}_$noise.las
[ -f "$cloud" ] || "$bin" synth shape "$shape" -n "$n" --noise "$noise" -o "$cloud" 2>/dev/null
for threads in 2 1; do
  for i in 1 2 3; do
    rm -rf "$work/run_$threads"
    "$bin" extract "$cloud" -o "$work/run_$threads" -q --threads $threads
    python3 - "$work/run_$threads/report.json" "$threads" <<'PY'
import json, sys
r = json.load(open(sys.argv[1])); p = r["pass_seconds"]; s = r["seconds"]
print(f"threads {sys.argv[2]}: total {r['total_seconds']:.2f} s | bucketing {p['bucketing']:.2f} statistics {p['statistics']:.2f} "
      f"residuals {p['residuals']:.2f} projection {p['projection']:.2f} curves {p['curves']:.2f} "
      f"(smoothing {s['smoothing']:.2f} growing {s['growing']:.2f} completion {s['completion']:.2f}) writing {p['writing']:.2f} "
      f"| peak RSS {r['peak_rss_bytes']/1e6:.0f} MB | {r['counts']['candidates']} candidates, {r['counts']['curves']} curves")
PY
  done
done
