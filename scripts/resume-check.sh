#!/usr/bin/env bash
# Kill -9 a run at N random moments, resuming each time, and compare the outputs byte for byte
# with an uninterrupted run.   scripts/resume-check.sh [WORKDIR] [POINTS] [KILLS]
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=$PWD/target/release/crease
work=${1:-$(mktemp -d)}
n=${2:-2000000}
kills=${3:-10}
mkdir -p "$work"
las=$work/scene_$n.las
[ -f "$las" ] || "$bin" synth scene -n "$n" -o "$las" 2>/dev/null
args=(extract "$las" --memory 256M -q)
start=$(date +%s.%N)
rm -rf "$work/clean"  # (fresh: the same job in an old directory would resume)
"$bin" "${args[@]}" -o "$work/clean"
full=$(echo "$(date +%s.%N) - $start" | bc)
echo "uninterrupted run: $full s"
rm -rf "$work/killed"
landed=0
for k in $(seq 1 "$kills"); do
  delay=$(python3 -c "import random; random.seed($k); print(round($full * random.uniform(0.03, 0.2), 2))")
  "$bin" "${args[@]}" -o "$work/killed" & pid=$!
  sleep "$delay"
  if kill -9 $pid 2>/dev/null; then
    landed=$((landed + 1))
    echo "kill $k after $delay s: $("$bin" status "$work/killed" 2>/dev/null | head -1)"
  fi
  wait $pid 2>/dev/null || true
done
"$bin" "${args[@]}" -o "$work/killed"
for f in curves.obj curves.ply curves.geojson; do
  cmp "$work/clean/$f" "$work/killed/$f" && echo "$f: identical"
done
echo "$landed of $kills kills landed before the run finished"
