#!/usr/bin/env bash
# Memory against input size: for each size, a noisy scene with clutter (trees, grass, recessed
# windows: many edge points) is generated once and extracted with `--memory MEM`; prints the
# whole run's peak RSS, the own peaks of the tile passes, the curve stage, the outputs and the
# label pass (report.json), the seconds, the curve stage's growth blocks, and recall / precision
# against the scene's truth. EXTRA is passed to extract (e.g. --label-points).
# The peak should stay flat as the input grows. Each run directory is removed once scored
# (the clouds are kept in WORKDIR: about 20 bytes a point).
#   scripts/scale-check.sh [WORKDIR] [SIZES] [MEM] [NOISE] [EXTRA]
#   e.g. scripts/scale-check.sh /tmp/scale "10000000 100000000 300000000" 512M 0.01
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=$PWD/target/release/crease
work=${1:-$(mktemp -d)}
sizes=${2:-10000000 100000000}
mem=${3:-512M}
noise=${4:-0.01}
extra=${5:-}
mkdir -p "$work"
echo "| points | edge points | blocks | vertices | peak RSS | tile passes | curve stage | outputs | labels | seconds | curve stage s | recall | precision |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|"
for n in $sizes; do
  las=$work/scene_${n}_$noise.las
  [ -f "$las" ] || "$bin" synth scene -n "$n" --noise "$noise" --clutter -o "$las" > /dev/null
  out=$work/run_$n
  rm -rf "$out"  # (fresh: the same job in an old directory would resume, not be measured)
  # shellcheck disable=SC2086  # (EXTRA is a list of arguments)
  "$bin" extract "$las" -o "$out" --memory "$mem" -q $extra
  # Truth tolerance 0.1 m (the scene is in metres; --diag 10 makes --tol 0.01 mean 10 cm).
  "$bin" eval --truth "${las%.las}.truth.obj" --curves "$out/curves.obj" --diag 10 --json > "$work/eval_$n.json"
  python3 - "$out/report.json" "$work/eval_$n.json" "$out/curves.obj" <<'PY'
import json, sys
r, e = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
c, mb = r["counts"], lambda k: f"{r[k] / 1e6:.0f} MB"
vertices = sum(1 for line in open(sys.argv[3]) if line.startswith("v "))
print(f"| {c['points']:,} | {c['edge_points']:,} | {c['blocks']} | {vertices:,} | {mb('peak_rss_bytes')} | {mb('peak_rss_tiles_bytes')} "
      f"| {mb('peak_rss_curves_bytes')} | {mb('peak_rss_outputs_bytes')} | {mb('peak_rss_labels_bytes')} | {r['total_seconds']:.0f} | {r['pass_seconds']['curves']:.1f} "
      f"| {e['recall']:.4f} | {e['precision']:.4f} |")
PY
  rm -rf "$out"
done
