#!/usr/bin/env bash
# Byte-for-byte comparison of two crease binaries on every quality cloud (shapes and the shared
# meshes at 500 k points and four noise levels, wedges, outliers and sampling variants), the
# 5 M scene at 1, 4, 16 and 64 tiles, and a noisy cloud at 140, 1008 and 6240 tiles: for a
# change that must not change any output (a refactor).   scripts/same-outputs.sh OLD NEW [WORKDIR]
set -euo pipefail
old=$(realpath "$1"); new=$(realpath "$2")
cd "$(dirname "$0")/.."
work=${3:-$(mktemp -d)}
meshes=$(realpath ../shared/data/meshes 2>/dev/null || true)
mkdir -p "$work"
outputs() { # BIN OUTDIR: runs everything with BIN, prints the md5 of every output
  local bin=$1 out=$2 n=500000
  gen() { [ -f "$1" ] || "${@:2}" -o "$1" 2>/dev/null; }
  row() { rm -rf "$out/$1"; "$bin" extract "$2" -o "$out/$1" -q "${@:3}"; }
  for noise in 0 0.005 0.01 0.02; do
    for s in cube chamfer holecube cylinder step octahedron fandisk; do
      c=$work/${s}_$noise.las; gen "$c" "$old" synth shape $s -n $n --noise $noise; row ${s}_$noise "$c"
    done
    if [ -n "$meshes" ]; then
      for m in anchor part joint turbine pinion; do
        c=$work/${m}_$noise.las; gen "$c" "$old" synth mesh "$meshes/$m.off" -n $n --noise $noise; row ${m}_$noise "$c"
      done
    fi
  done
  for a in 25 45 60 90 110 140 150 160 170; do
    c=$work/wedge$a.las; gen "$c" "$old" synth shape wedge --angle $a -n $n; row wedge$a "$c"
  done
  for kind in "--outliers 0.05" "--sampling scanlines" "--sampling nonuniform"; do
    tag=$(echo $kind | tr -d ' -'); c=$work/fandisk_$tag.las
    gen "$c" "$old" synth shape fandisk -n $n $kind; row fandisk_$tag "$c"
  done
  las=$work/scene_5000000.las; gen "$las" "$old" synth scene -n 5000000
  side=$(python3 -c "import json,subprocess;b=json.loads(subprocess.check_output(['$bin','info','--json','$las']))[0]['bounds'];print(max(b['max'][0]-b['min'][0], b['max'][1]-b['min'][1]))")
  for k in 1 2 4 8; do
    row scene_t$k "$las" --tile-size "$(python3 -c "print($side / $k * 1.0001 if $k > 1 else $side * 2)")"
  done
  for s in 0.3 0.15 0.08; do row noisytile_$s "$work/fandisk_0.01.las" --tile-size $s; done
  (cd "$out" && md5sum */curves.obj */curves.ply */curves.geojson | sort -k2)
}
outputs "$old" "$work/old" > "$work/old.md5"
outputs "$new" "$work/new" > "$work/new.md5"
if diff "$work/old.md5" "$work/new.md5"; then
  echo "all $(wc -l < "$work/new.md5") outputs identical"
else
  echo "outputs differ (above)"; exit 1
fi
