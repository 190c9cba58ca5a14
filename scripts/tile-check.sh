#!/usr/bin/env bash
# Tile independence on a synthetic scene: extraction with tile sizes giving 1, 4, 16 and 64+
# tiles; curve counts, and the largest distance from a vertex of one result to the other's
# curves (both ways), in units of the spacing kappa.
#   scripts/tile-check.sh [WORKDIR] [POINTS] [CLOUD]
# CLOUD: check this cloud instead of the scene (e.g. `crease synth scene --clutter`, or a
# noisy shape).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=$PWD/target/release/crease
work=${1:-$(mktemp -d)}
n=${2:-5000000}
mkdir -p "$work"
las=${3:-$work/scene_$n.las}
[ -f "$las" ] || "$bin" synth scene -n "$n" -o "$las" 2>/dev/null
side=$(python3 -c "import json,subprocess;i=json.loads(subprocess.check_output(['$bin','info','--json','$las']))[0]['bounds'];print(max(i['max'][0]-i['min'][0], i['max'][1]-i['min'][1]))")
for k in 1 2 4 8; do
  size=$(python3 -c "print($side / $k * 1.0001 if $k > 1 else $side * 2)")
  rm -rf "$work/t$k"  # (fresh: the same job in an old directory would resume)
  "$bin" extract "$las" -o "$work/t$k" --tile-size "$size" -q
done
python3 - "$work" <<'PY'
import json, math, sys
def read(p):
    v, L = [], []
    for line in open(p):
        t = line.split()
        if t and t[0] == 'v': v.append(tuple(map(float, t[1:4])))
        if t and t[0] == 'l': L.append([v[int(i) - 1] for i in t[1:]])
    return L
def directed(a, b):
    # vertex-to-segment distances through a grid of segments
    cell = 1.0; grid = {}
    segs = [(l[i], l[i + 1]) for l in b for i in range(len(l) - 1)]
    for k, (s, e) in enumerate(segs):
        lo = [math.floor(min(s[d], e[d]) / cell) for d in range(3)]; hi = [math.floor(max(s[d], e[d]) / cell) for d in range(3)]
        for x in range(lo[0], hi[0] + 1):
            for y in range(lo[1], hi[1] + 1):
                for z in range(lo[2], hi[2] + 1):
                    grid.setdefault((x, y, z), []).append(k)
    def dist(p):
        c = [math.floor(p[d] / cell) for d in range(3)]; best = math.inf
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    for k in grid.get((c[0] + dx, c[1] + dy, c[2] + dz), []):
                        s, e = segs[k]; ab = [e[d] - s[d] for d in range(3)]; L2 = sum(x * x for x in ab)
                        t = 0 if L2 == 0 else max(0, min(1, sum((p[d] - s[d]) * ab[d] for d in range(3)) / L2))
                        best = min(best, math.dist(p, [s[d] + t * ab[d] for d in range(3)]))
        return best
    return max(dist(p) for l in a for p in l)
w = sys.argv[1]
ref = read(f"{w}/t1/curves.obj"); kappa = json.load(open(f"{w}/t1/report.json"))["params"]["kappa"]
for k in (1, 2, 4, 8):
    r = json.load(open(f"{w}/t{k}/report.json")); c = read(f"{w}/t{k}/curves.obj")
    print(f"{r['tiles']:>4} tiles: {len(c)} curves (1 tile: {len(ref)}), max vertex distance {directed(c, ref)/kappa:.3f} / {directed(ref, c)/kappa:.3f} kappa, {r['total_seconds']:.1f} s")
PY
