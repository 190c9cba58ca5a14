#!/usr/bin/env python3
"""Quality over a corpus of machined parts, per noise level: median and 10th percentile of
recall, resolvable recall and precision, and the time, as DESIGN section 4 asks (a corpus is
scored by its spread, not by a mean that one good part lifts).

A corpus is a folder of NAME.off meshes, each with NAME.truth.obj (the exact B-rep edges) and
optionally NAME.json (its `bbox_diag` is the length unit dB), as `../shared/data/cad/` or the
output of `../shared/tools/cad_corpus.py OUT --seed S --count N`.

    scripts/corpus.py [CORPUS ...] [--work DIR] [--points 500000] [--levels "0 k1 k2 k4 0.005 0.01 0.02"]
                      [--bin target/release/crease] [--json rows.json] [-- EXTRACT_ARGS...]

Levels: 0 (noise-free), kN (uniform-ball noise of N point spacings), a number (Daniels noise in
dB, bounding-box diagonals). Clouds are sampled once per part and level and kept in the work
folder (reused by later runs and other builds); runs are redone each time. Arguments after --
go to every `crease extract` (for example `--model surfaces`).
"""
import argparse
import hashlib
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path


def quantile(xs, q):
    """The q-quantile by linear interpolation between order statistics (numpy's default)."""
    xs = sorted(xs)
    if not xs:
        return float("nan")
    pos = q * (len(xs) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(xs) - 1)
    return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)


def noise_args(level):
    if level == "0":
        return []
    if level.startswith("k"):
        return ["--noise-spacing", level[1:]]
    return ["--noise", level]


def setup(bin_arg, work_arg):
    """The binary to score (this tree's release build unless one is given) and the cache folder
    of clouds, made if need be."""
    root = Path(__file__).resolve().parent.parent
    if bin_arg:
        binary = Path(bin_arg).resolve()
    else:
        subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=root, check=True)
        binary = root / "target/release/crease"
    work = Path(work_arg or os.environ.get("TMPDIR", "/tmp")) / "crease-corpus"
    work.mkdir(parents=True, exist_ok=True)
    return binary, work


def sampled(binary, work, off, level, points):
    """The cloud of part `off` at noise `level`, sampled once and kept in `work`."""
    cloud = work / f"{off.parent.name}_{off.stem}_{level}_{points}.las"
    if not cloud.exists():
        part = cloud.with_suffix(f".part{os.getpid()}.las")
        subprocess.run([str(binary), "synth", "mesh", str(off), "-n", str(points), "-o", str(part)]
                       + noise_args(level), check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        part.with_suffix(".truth.obj").unlink()
        part.rename(cloud)
    return cloud


def part_diag(off):
    meta = off.with_suffix(".json")
    if meta.exists():
        return json.loads(meta.read_text())["bbox_diag"]
    lo, hi = [float("inf")] * 3, [float("-inf")] * 3
    for line in off.with_suffix("").with_suffix(".truth.obj").read_text().splitlines():
        if line.startswith("v "):
            v = [float(t) for t in line.split()[1:4]]
            lo = [min(a, b) for a, b in zip(lo, v)]
            hi = [max(a, b) for a, b in zip(hi, v)]
    return sum((b - a) ** 2 for a, b in zip(lo, hi)) ** 0.5


def arguments(doc, levels):
    """The arguments every corpus script takes: corpus folders, cache folder, points, levels,
    binary."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("corpus", nargs="*", default=["../shared/data/cad"])
    ap.add_argument("--work", default=None)
    ap.add_argument("--points", type=int, default=500000)
    ap.add_argument("--levels", default=levels)
    ap.add_argument("--bin", default=None)
    return ap


def main():
    ap = arguments(__doc__, "0 k1 k2 k4 0.005 0.01 0.02")
    ap.add_argument("--seed", default="1", help="the extraction's --seed")
    ap.add_argument("--json", default=None,
                    help="also write every part's row here, a JSON object a line, as each is scored; "
                         "rows already there from the same build and arguments are kept and not run "
                         "again (an interrupted table resumes)")
    ap.add_argument("--only", default=None, help="only parts whose name contains this")
    args, extra = ap.parse_known_args()
    extra = [a for a in extra if a != "--"]
    binary, work = setup(args.bin, args.work)
    tag = hashlib.md5(binary.read_bytes() + " ".join(extra).encode()).hexdigest()[:8]
    parts = []
    for c in args.corpus:
        for off in sorted(Path(c).glob("*.off")):
            if off.with_suffix("").with_suffix(".truth.obj").exists() and (not args.only or args.only in off.stem):
                parts.append(off.resolve())
    if not parts:
        sys.exit(f"corpus.py: no NAME.off with NAME.truth.obj in {args.corpus}")
    rows = []
    done = {}
    if args.json and Path(args.json).exists():
        for line in Path(args.json).read_text().splitlines():
            r = json.loads(line)
            # (Only rows of this build and these arguments: a file shared by two builds is not
            # read as either's.)
            if r.get("build", tag) == tag:
                done[(r["part"], r["level"])] = r
    levels = args.levels.split()
    for level in levels:
        for off in parts:
            name = f"{off.parent.name}_{off.stem}"
            if (name, level) in done:
                rows.append(done[(name, level)])
                continue
            cloud = sampled(binary, work, off, level, args.points)
            out = work / f"run_{tag}_{name}_{level}"
            shutil.rmtree(out, ignore_errors=True)
            t0 = time.perf_counter()
            subprocess.run([str(binary), "extract", str(cloud), "-o", str(out), "-q", "--seed", args.seed] + extra,
                           check=True)
            seconds = time.perf_counter() - t0
            report = json.loads((out / "report.json").read_text())
            diag = part_diag(off)
            if level == "0":
                radius = 0.0
            elif level.startswith("k"):
                radius = float(level[1:]) * report["params"]["kappa"] / diag
            else:
                radius = float(level)
            truth = off.with_suffix("").with_suffix(".truth.obj")
            ev = json.loads(subprocess.run(
                [str(binary), "eval", "--truth", str(truth), "--curves", str(out / "curves.obj"), "--diag", str(diag),
                 "--resolvable", str(max(3 * radius, 1e-9)), "--json"], check=True, capture_output=True).stdout)
            res = ev.get("resolvable") or {}
            # (No curve at all has no precision; it counts as 0, a miss, not as a part left out. A
            # part whose truth is all closer than the resolvable separation has no resolvable
            # recall: its recall stands for it.)
            row = dict(build=tag, part=name, level=level, recall=ev["recall"],
                       resolvable=res["recall"] if res.get("recall") is not None else ev["recall"],
                       share=res.get("share"), precision=ev["precision"] if ev["precision"] is not None else 0.0, curves=ev["curves"],
                       truth_curves=ev["truth_curves"], seconds=seconds,
                       edge_points=report.get("counts", {}).get("edge_points"))
            rows.append(row)
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps(row) + "\n")
            print(f"  {name} {level}: recall {row['recall']:.3f} resolvable {row['resolvable']:.3f} "
                  f"precision {row['precision']:.3f} {seconds:.2f} s", file=sys.stderr, flush=True)
            shutil.rmtree(out, ignore_errors=True)
    print(f"{len(parts)} parts, {args.points} points, `crease extract {' '.join(extra)}`; median / 10th percentile")
    print()
    print("| noise | recall | resolvable recall | precision | seconds (median / max) |")
    print("|---|---|---|---|---|")
    for level in levels:
        rs = [r for r in rows if r["level"] == level]
        f = lambda k: f"{statistics.median(r[k] for r in rs):.3f} / {quantile([r[k] for r in rs], 0.1):.3f}"
        t = [r["seconds"] for r in rs]
        label = f"{level[1:]} spacings" if level.startswith("k") else ("none" if level == "0" else f"{level} dB")
        print(f"| {label} | {f('recall')} | {f('resolvable')} | {f('precision')} | {statistics.median(t):.2f} / {max(t):.2f} |")


if __name__ == "__main__":
    main()
