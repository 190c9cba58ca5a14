#!/usr/bin/env python3
"""What the Python module costs over the command line: `crease.extract` on a 500 k-point array
against `crease extract` on the same cloud as a LAS file, both timed in one run, alternating,
on an otherwise idle machine. The module should be within 5 % of the binary (it runs the same
pipeline in memory; the binary also reads the file and writes its outputs).

    pip install . laspy && cargo build --release
    python3 scripts/python-overhead.py [--bin target/release/crease] [-n 500000] [--repeat 5]

Prints each time, the medians and their ratio, and checks that both gave the same curves; exits 1
if the module is more than 5 % slower.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import crease
import laspy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    a = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default_bin = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target")) / "release" / "crease"
    a.add_argument("--bin", type=Path, default=default_bin, help="the crease binary (default: %(default)s)")
    a.add_argument("-n", type=int, default=500_000, help="points (default: %(default)s)")
    a.add_argument("--shape", default="fandisk", help="the synthetic shape (default: %(default)s)")
    a.add_argument("--repeat", type=int, default=5, help="timed runs of each (default: %(default)s)")
    a.add_argument("--limit", type=float, default=1.05, help="largest ratio module / binary that passes (default: %(default)s)")
    args = a.parse_args()
    with tempfile.TemporaryDirectory(prefix="crease-overhead-") as tmp:
        las = Path(tmp) / "cloud.las"
        subprocess.run([str(args.bin), "synth", "shape", args.shape, "-n", str(args.n), "-o", str(las)], check=True, capture_output=True)
        points = crease._as_points(laspy.read(las))
        run = Path(tmp) / "run"
        cli_times, py_times = [], []
        # (One untimed run of each first: page cache, the module's import, the allocator.)
        for k in range(args.repeat + 1):
            t = time.perf_counter()
            subprocess.run([str(args.bin), "extract", str(las), "-o", str(run), "-q", "--force"], check=True)
            cli = time.perf_counter() - t
            t = time.perf_counter()
            curves = crease.extract(points)
            py = time.perf_counter() - t
            if k > 0:
                cli_times.append(cli)
                py_times.append(py)
                print(f"run {k}: crease extract {cli:.3f} s, crease.extract {py:.3f} s", flush=True)
        same = len(curves) == len(crease.read(run)) and all(np.array_equal(x.points, y.points) for x, y in zip(curves, crease.read(run)))
    cli_m, py_m = statistics.median(cli_times), statistics.median(py_times)
    ratio = py_m / cli_m
    print(f"{args.n} points, {len(curves)} curves (the same as the binary's: {same})")
    print(f"median: crease extract {cli_m:.3f} s, crease.extract {py_m:.3f} s; ratio {ratio:.3f} (limit {args.limit})")
    return 0 if ratio <= args.limit and same else 1


if __name__ == "__main__":
    sys.exit(main())
