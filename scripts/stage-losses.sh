#!/usr/bin/env bash
# Where the truth is lost, stage by stage: runs `crease extract --debug-dir` on CLOUD and scores
# the edge cloud, the smoothed edge cloud and the grown polylines against TRUTH (the share of
# the truth with a point within TOL dB, and the share of points within TOL of the truth), then
# the final curves with `crease eval`. Needs python3 with numpy and scipy.
#   scripts/stage-losses.sh CLOUD TRUTH [TOL] [WORKDIR] [-- EXTRACT_ARGS...]
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=$PWD/target/release/crease
cloud=$1 truth=$2 tol=${3:-0.01} work=${4:-$(mktemp -d)}
shift $(( $# < 4 ? $# : 4 ))
[ "${1:-}" = "--" ] && shift
rm -rf "$work/run" "$work/debug"
"$bin" extract "$cloud" -o "$work/run" -q --debug-dir "$work/debug" "$@"
python3 - "$truth" "$tol" "$work/debug" <<'PY'
import sys, numpy as np
from scipy.spatial import cKDTree
truth, tol, debug = sys.argv[1], float(sys.argv[2]), sys.argv[3]
def read_obj(path):
    v, lines = [], []
    for line in open(path):
        if line.startswith("v "):
            v.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("l "):
            lines.append([int(x) - 1 for x in line.split()[1:]])
    return np.array(v).reshape(-1, 3), lines
def sample(v, lines, step):
    out = []
    for l in lines:
        for a, b in zip(l[:-1], l[1:]):
            n = max(1, int(np.linalg.norm(v[b] - v[a]) / step) + 1)
            out.extend(v[a] + (v[b] - v[a]) * t for t in np.arange(n) / n)
    return np.array(out).reshape(-1, 3)
tv, tl = read_obj(truth)
d = tol * np.linalg.norm(tv.max(0) - tv.min(0))
ts = sample(tv, tl, d / 4)
tree = cKDTree(ts)
print(f"{'stage':<10} {'truth covered':>14} {'points on truth':>16} {'points':>8}")
for name in ["edges", "smoothed", "grown"]:
    v, lines = read_obj(f"{debug}/{name}.obj")
    pts = sample(v, lines, d / 4) if lines else v
    if len(pts) == 0:
        print(f"{name:<10} {'-':>14} {'-':>16} {0:>8}")
        continue
    covered = (cKDTree(pts).query(ts)[0] <= d).mean()
    on = (tree.query(pts)[0] <= d).mean()
    print(f"{name:<10} {covered:>14.4f} {on:>16.4f} {len(v):>8}")
PY
echo "final curves (crease eval):"
"$bin" eval --truth "$truth" --curves "$work/run/curves.obj" --tol "$tol" | head -3
