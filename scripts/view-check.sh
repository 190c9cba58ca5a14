#!/usr/bin/env bash
# Checks `crease view` in a browser: writes RUN/view.html for each finished run, opens it in
# headless Chromium (Debian's `chromium`, WebGL through SwiftShader) with the network off, takes
# a screenshot, and checks that points and coloured curves were drawn.
#
#   scripts/view-check.sh RUN...        (screenshots in RUN/view-check.png)
set -euo pipefail
cd "$(dirname "$0")/.."
command -v chromium >/dev/null || { echo "needs chromium (apt-get install chromium)"; exit 2; }
cargo build --release --quiet
status=0
for run in "$@"; do
  ./target/release/crease view "$run" 2>/dev/null
  shot="$run/view-check.png"
  rm -f "$shot"
  timeout 120 chromium --headless=new --no-sandbox --use-angle=swiftshader --enable-unsafe-swiftshader \
    --proxy-server=127.0.0.1:9 --window-size=1200,800 --virtual-time-budget=5000 \
    --screenshot="$shot" "file://$(realpath "$run")/view.html" >/dev/null 2>&1 || true
  python3 - "$shot" "$run" <<'PY' || status=1
import sys, zlib, struct
path, run = sys.argv[1], sys.argv[2]
try:
    data = open(path, 'rb').read()
except OSError:
    print(f"FAIL {run}: no screenshot"); sys.exit(1)
# Decode the PNG (8-bit RGB or RGBA, no interlace) with the standard library only.
w, h, depth, ctype = struct.unpack('>IIBB', data[16:26])
idat = b''.join(data[i + 8:i + 8 + struct.unpack('>I', data[i:i + 4])[0]] for i in range(8, len(data))
                if data[i + 4:i + 8] == b'IDAT' and i + 8 <= len(data))
raw = zlib.decompress(idat)
bpp = 4 if ctype == 6 else 3
stride = w * bpp
rows, prev = [], bytearray(stride)
k = 0
for y in range(h):
    f = raw[k]; line = bytearray(raw[k + 1:k + 1 + stride]); k += 1 + stride
    for x in range(stride):
        a = line[x - bpp] if x >= bpp else 0
        b = prev[x]; c = prev[x - bpp] if x >= bpp else 0
        if f == 1: line[x] = (line[x] + a) & 255
        elif f == 2: line[x] = (line[x] + b) & 255
        elif f == 3: line[x] = (line[x] + (a + b) // 2) & 255
        elif f == 4:
            p = a + b - c; pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
            line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
    rows.append(line); prev = line
grey = colour = 0
for line in rows[60:]:          # below the caption
    for x in range(0, stride, bpp):
        r, g, b = line[x], line[x + 1], line[x + 2]
        if max(r, g, b) - min(r, g, b) > 60: colour += 1
        elif max(r, g, b) < 235: grey += 1
total = w * (h - 60)
ok = grey > 0.02 * total and colour > 200
print(f"{'ok  ' if ok else 'FAIL'} {run}: {w}x{h}, points drawn on {100 * grey / total:.1f} % of the view, curve pixels {colour}")
sys.exit(0 if ok else 1)
PY
done
exit $status
