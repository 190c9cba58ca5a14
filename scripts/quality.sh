#!/usr/bin/env bash
# Quality table: synthetic shapes and the shared CAD meshes at 500 k points, noise-free, with
# noise of 1, 2 and 4 point spacings (kappa), and with Daniels noise of 0.005, 0.01 and 0.02 dB;
# scored by `crease eval` (DESIGN.md section 4), with recall also over the resolvable truth
# (features farther apart than 3 noise radii: `crease eval --resolvable`). Prints Markdown.
#   scripts/quality.sh [WORKDIR] [POINTS] [SEED] [NOISES]
# CREASE_BIN=path scores that binary instead of this tree's release build (to compare two builds
# on the same clouds; the clouds are kept in WORKDIR and reused, also by two such runs at once).
# SEED is the extraction's (`crease extract --seed`, the robust fits' random streams; the clouds
# are the same); NOISES defaults to "0 k1 k2 k4 0.005 0.01 0.02" (kN: N point spacings).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -n "${CREASE_BIN:-}" ]; then bin=$(realpath "$CREASE_BIN"); else cargo build --release --quiet; bin=$PWD/target/release/crease; fi
work=${1:-$(mktemp -d)}
n=${2:-500000}
seed=${3:-1}
noises=${4:-0 k1 k2 k4 0.005 0.01 0.02}
mkdir -p "$work"
# (Run directories named by the binary too, so that two builds scored in one WORKDIR at once,
# sharing its clouds, do not overwrite each other's runs.)
bin_tag=$(md5sum "$bin" | cut -c1-8)
meshes=../shared/data/meshes
echo "| cloud | noise | curves (truth) | recall | resolvable recall (share) | precision | mean dB | max dB | seconds |"
echo "|---|---|---|---|---|---|---|---|---|"
noise_args() { case $1 in k*) echo "--noise-spacing ${1#k}" ;; *) echo "--noise $1" ;; esac; }
make_cloud() { # path, then the `crease synth` arguments; written aside, then moved into place
  local c=$1 part=${1%.las}.part$$.las; shift
  [ -f "$c" ] && return
  "$bin" synth "$@" -o "$part" 2>/dev/null
  mv "${part%.las}.truth.obj" "${c%.las}.truth.obj"
  mv "$part" "$c"
}
row() { # name noise cloud truth
  local name=$1 noise=$2 cloud=$3 truth=$4 out=$work/out_${bin_tag}_${1}_$2_s$seed
  rm -rf "$out"  # (fresh: the same job in an old directory would resume)
  "$bin" extract "$cloud" -o "$out" -q --seed "$seed"
  # The resolvable separation: 3 noise radii, in dB units (kappa from the run's report).
  local sep
  sep=$(python3 - "$noise" "$out/report.json" "$cloud" "$bin" <<'PY'
import json, subprocess, sys
noise, report, cloud, binary = sys.argv[1:5]
b = json.loads(subprocess.check_output([binary, "info", "--json", cloud]))[0]["bounds"]
diag = sum((b["max"][k] - b["min"][k]) ** 2 for k in range(3)) ** 0.5
if noise.startswith("k"):
    r = float(noise[1:]) * json.load(open(report))["params"]["kappa"] / diag
else:
    r = float(noise)
print(max(3 * r, 1e-9))
PY
)
  "$bin" eval --truth "$truth" --curves "$out/curves.obj" --resolvable "$sep" --json > "$out/eval.json"
  python3 - "$name" "$noise" "$out/eval.json" "$out/report.json" <<'PY'
import json, sys
e = json.load(open(sys.argv[3])); r = json.load(open(sys.argv[4]))
f = lambda x, d=4: "n/a" if x is None else f"{x:.{d}f}"
res = e.get("resolvable") or {}
print(f"| {sys.argv[1]} | {sys.argv[2]} | {e['curves']} ({e['truth_curves']}) | {f(e['recall'])} | {f(res.get('recall'))} ({f(res.get('share'), 2)}) | {f(e['precision'])} | {f(e['mean_distance'],5)} | {f(e['max_distance'],4)} | {r['total_seconds']:.2f} |")
PY
}
for noise in $noises; do
  for s in cube chamfer holecube cylinder step octahedron fandisk plate blade; do
    c=$work/${s}_${noise}.las
    make_cloud "$c" shape $s -n $n $(noise_args $noise)
    row $s $noise "$c" "${c%.las}.truth.obj"
  done
  if [ -d "$meshes" ]; then
    for m in anchor part joint turbine pinion; do
      c=$work/${m}_${noise}.las
      make_cloud "$c" mesh "$meshes/$m.off" -n $n $(noise_args $noise)
      row $m $noise "$c" "${c%.las}.truth.obj"
    done
  fi
done
case " $noises " in *" 0 "*) ;; *) exit 0 ;; esac
for a in 25 45 60 90 110 140 150 160 170; do
  c=$work/wedge${a}.las
  make_cloud "$c" shape wedge --angle $a -n $n
  row wedge$a 0 "$c" "${c%.las}.truth.obj"
done
for kind in "--outliers 0.05" "--sampling scanlines" "--sampling nonuniform"; do
  tag=$(echo $kind | tr -d ' -')
  c=$work/fandisk_${tag}.las
  make_cloud "$c" shape fandisk -n $n $kind
  row fandisk_$tag 0 "$c" "${c%.las}.truth.obj"
done
