#!/usr/bin/env bash
# Quality table: synthetic shapes and the shared CAD meshes at 500 k points, at noise levels
# 0, 0.005, 0.01, 0.02 dB; scored by `crease eval` (DESIGN.md section 4). Prints Markdown.
#   scripts/quality.sh [WORKDIR] [POINTS]
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=$PWD/target/release/crease
work=${1:-$(mktemp -d)}
n=${2:-500000}
mkdir -p "$work"
meshes=../shared/data/meshes
echo "| cloud | noise | curves (truth) | recall | precision | mean dB | max dB | seconds |"
echo "|---|---|---|---|---|---|---|---|"
row() { # name noise cloud truth
  local name=$1 noise=$2 cloud=$3 truth=$4 out=$work/out_${1}_$2
  rm -rf "$out"  # (fresh: the same job in an old directory would resume)
  "$bin" extract "$cloud" -o "$out" -q
  "$bin" eval --truth "$truth" --curves "$out/curves.obj" --json > "$out/eval.json"
  python3 - "$name" "$noise" "$out/eval.json" "$out/report.json" <<'PY'
import json, sys
e = json.load(open(sys.argv[3])); r = json.load(open(sys.argv[4]))
f = lambda x, d=4: "n/a" if x is None else f"{x:.{d}f}"
print(f"| {sys.argv[1]} | {sys.argv[2]} | {e['curves']} ({e['truth_curves']}) | {f(e['recall'])} | {f(e['precision'])} | {f(e['mean_distance'],5)} | {f(e['max_distance'],4)} | {r['total_seconds']:.2f} |")
PY
}
for noise in 0 0.005 0.01 0.02; do
  for s in cube chamfer holecube cylinder step octahedron fandisk; do
    c=$work/${s}_$noise.las
    [ -f "$c" ] || "$bin" synth shape $s -n $n --noise $noise -o "$c" 2>/dev/null
    row $s $noise "$c" "${c%.las}.truth.obj"
  done
  if [ -d "$meshes" ]; then
    for m in anchor part joint turbine pinion; do
      c=$work/${m}_$noise.las
      [ -f "$c" ] || "$bin" synth mesh "$meshes/$m.off" -n $n --noise $noise -o "$c" 2>/dev/null
      row $m $noise "$c" "${c%.las}.truth.obj"
    done
  fi
done
for a in 25 45 60 90 110 140 150 160 170; do
  c=$work/wedge$a.las
  [ -f "$c" ] || "$bin" synth shape wedge --angle $a -n $n -o "$c" 2>/dev/null
  row wedge$a 0 "$c" "${c%.las}.truth.obj"
done
for kind in "--outliers 0.05" "--sampling scanlines" "--sampling nonuniform"; do
  tag=$(echo $kind | tr -d ' -')
  c=$work/fandisk_$tag.las
  [ -f "$c" ] || "$bin" synth shape fandisk -n $n $kind -o "$c" 2>/dev/null
  row fandisk_$tag 0 "$c" "${c%.las}.truth.obj"
done
