#!/usr/bin/env bash
# Fuzzes crease's readers (LAS, LAZ, PLY, E57, text) and a resumed run's manifest with cargo-fuzz
# (libFuzzer, AddressSanitizer), each target for SECONDS, one after the other.
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]     (default: 300 s each; las laz ply e57 e57_structure
#                                              text manifest)
#
# Needs a nightly toolchain (`rustup toolchain install nightly`) and `cargo install cargo-fuzz`.
# Seeds are generated (small synthetic clouds in each format) plus the small files of
# ../shared/data/real when it is there. Corpora and crashes stay in scripts/fuzz/{corpus,artifacts}
# (not committed); a crash's input is printed with the command that replays it.
# Prints, per target: executions, seconds, corpus size and crashes found.
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_EACH=${1:-300}
shift || true
TARGETS=("$@")
[ ${#TARGETS[@]} -gt 0 ] || TARGETS=(las laz ply e57 e57_structure text manifest)
FUZZ=scripts/fuzz
SHARED=../shared/data/real

cargo build --release --quiet
CREASE="${CARGO_TARGET_DIR:-target}/release/crease"
seeds=$(mktemp -d)
trap 'rm -rf "$seeds"' EXIT
for fmt in las laz ply; do mkdir -p "$FUZZ/corpus/$fmt"; done
mkdir -p "$FUZZ/corpus/manifest" "$FUZZ/corpus/e57" "$FUZZ/corpus/e57_structure" "$FUZZ/corpus/text"
printf 'x;y;z;class\n0.5;1;2;6\n1e3 2 3 4\n7\n' > "$FUZZ/corpus/text/seed-header.csv"
printf '3\n0 0 0 -10 1 2 3\n1 0 0 5 1 2 3\n0 1 0 5 1 2 3\n' > "$FUZZ/corpus/text/seed.pts"
# The e57 target patches a valid file of its own; its seed is 'no patch'.
printf '\377' > "$FUZZ/corpus/e57/seed-whole"
# The e57_structure target writes its own file from a flags byte, a point count, a declared
# count and bounds, then coordinates (see the target). Seeds as long as all of that (libFuzzer
# grows inputs only slowly past its seeds' length): 300 doubles as written, declared single,
# and with the record count and bounds replaced.
for flags in '\000' '\002' '\016' '\055'; do
  { printf "$flags\054\001"; printf '\377\377\377\377\000\000\000\000'; head -c 48 /dev/zero; seq 1 64 | tr '\n' ' '; } \
    > "$FUZZ/corpus/e57_structure/seed-flags-$(printf "$flags" | od -An -tu1 | tr -d ' ')"
done
# Small clouds: a few hundred points keep executions fast; libFuzzer grows inputs from them.
"$CREASE" synth shape cube -n 200 -o "$seeds/cube.las" 2>/dev/null
"$CREASE" synth shape fandisk -n 300 -o "$seeds/fandisk.ply" 2>/dev/null
cp "$seeds/cube.las" "$FUZZ/corpus/las/seed-cube.las"
cp "$seeds/fandisk.ply" "$FUZZ/corpus/ply/seed-fandisk.ply"
printf 'ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n' > "$FUZZ/corpus/ply/seed-ascii.ply"
printf 'ply\nformat binary_big_endian 1.0\ncomment seed\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\nproperty uchar classification\nend_header\n' > "$FUZZ/corpus/ply/seed-be.ply"
head -c 25 /dev/zero >> "$FUZZ/corpus/ply/seed-be.ply"
# LAZ: convert the LAS seed through crease's own writer (via a synth run to .laz is not offered),
# so take the shared small LAZ files; the LAS seeds also get the first 8 KiB of each shared LAS
# (headers, VLRs and EVLR offsets of every version) when ../shared is there.
if [ -d "$SHARED" ]; then
  for f in "$SHARED"/*.laz; do
    [ "$(stat -c %s "$f")" -le 250000 ] && cp "$f" "$FUZZ/corpus/laz/seed-$(basename "$f")"
  done
  for f in "$SHARED"/*.las; do head -c 8192 "$f" > "$FUZZ/corpus/las/seed-head-$(basename "$f")"; done
fi
[ -n "$(ls "$FUZZ/corpus/laz")" ] || { echo "note: no LAZ seed (../shared not found): the laz target starts from LAS seeds"; cp "$seeds/cube.las" "$FUZZ/corpus/laz/seed-cube.laz"; }
# The manifest target's seed: the manifest of a run like the target's set-up run (a 4,000-point
# cube in tiles of 0.45).
"$CREASE" synth shape cube -n 4000 -o "$seeds/cube.ply" 2>/dev/null
"$CREASE" extract "$seeds/cube.ply" --tile-size 0.45 -o "$seeds/run" 2>/dev/null >/dev/null
cp "$seeds/run/manifest.json" "$FUZZ/corpus/manifest/seed-cube.json"

# Build first: a target that does not build must not count as fuzzed.
for t in "${TARGETS[@]}"; do
  cargo +nightly fuzz build --fuzz-dir "$FUZZ" -O "$t" || { echo "fuzz target $t does not build"; exit 1; }
done

status=0
for t in "${TARGETS[@]}"; do
  log="$FUZZ/artifacts/$t.log"
  mkdir -p "$FUZZ/artifacts/$t"
  echo "== $t: ${SECONDS_EACH} s"
  # -timeout: an execution over 10 s is a hang; -rss_limit_mb: an input that makes crease
  # allocate gigabytes is a finding too.
  if ! cargo +nightly fuzz run --fuzz-dir "$FUZZ" -O "$t" "$FUZZ/corpus/$t" -- \
      -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
      -artifact_prefix="$FUZZ/artifacts/$t/" -print_final_stats=1 > "$log" 2>&1; then
    status=1
  fi
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo '?')
  echo "   executions: $runs; corpus: $(ls "$FUZZ/corpus/$t" | wc -l) inputs; crashes: $(ls "$FUZZ/artifacts/$t" | wc -l)"
  for a in "$FUZZ/artifacts/$t"/*; do
    [ -e "$a" ] && echo "   replay: cargo +nightly fuzz run --fuzz-dir $FUZZ -O $t $a"
  done
  grep -m3 -E 'panicked|ERROR: |SUMMARY' "$log" | sed 's/^/   /' || true
done
exit $status
