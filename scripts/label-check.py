#!/usr/bin/env python3
"""Checks a labelled copy that `crease extract --label-points` wrote, read by laspy (an
independent LAS 1.4 reader), against the input it was made from.

    pip install "laspy[lazrs]"
    scripts/label-check.py RUN/labels/scan.laz scan.las [--tolerance T]

Checks: the point count; the coordinates, equal to the input's (for a LAS/LAZ input, the
stored integers and every other dimension of the input too, in order); the three extra
dimensions, named and typed as crease writes them (edge_distance float64, curve_id int32, edge
uint8); edge = 1 exactly where edge_distance is within the tolerance (curves.json's, or
--tolerance; skipped without either), and curve_id -1 or a curve of the run's outputs. Prints
one line per check and exits 1 if any fails.
"""
import argparse
import json
import sys
from pathlib import Path

import laspy
import numpy as np

EXPECTED = {"edge_distance": np.dtype("float64"), "curve_id": np.dtype("int32"), "edge": np.dtype("uint8")}


def run_curve_ids(run):
    """The curve ids of the run's outputs (from curves.json or curves.geojson), if there."""
    for name, key in (("curves.json", "pieces"), ("curves.geojson", "features")):
        p = run / name
        if p.is_file():
            items = json.loads(p.read_text())[key]
            return {int(i["curve"] if key == "pieces" else i["properties"]["id"]) for i in items}, run / "curves.json"
    return None, run / "curves.json"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("labelled")
    ap.add_argument("input")
    ap.add_argument("--tolerance", type=float)
    a = ap.parse_args()
    out, inp = laspy.read(a.labelled), Path(a.input)
    failures = []

    def check(ok, what):
        print(("ok    " if ok else "FAIL  ") + what)
        if not ok:
            failures.append(what)

    check(out.header.version.major == 1 and out.header.version.minor == 4, f"LAS version {out.header.version}")
    extra = {d.name: d.dtype for d in out.point_format.extra_dimensions}
    for name, dt in EXPECTED.items():
        check(extra.get(name) == dt, f"extra dimension {name}: {extra.get(name)} (expected {dt})")
    n = len(out.points)
    if inp.suffix.lower() in (".las", ".laz"):
        src = laspy.read(inp)
        check(len(src.points) == n, f"point count {n} (input {len(src.points)})")
        check(out.header.point_format.id == src.header.point_format.id, f"point format {out.header.point_format.id} (input {src.header.point_format.id})")
        same = all(np.array_equal(out[d], src[d]) for d in ("X", "Y", "Z")) and all(np.array_equal(out[d], src[d]) for d in ("x", "y", "z"))
        check(same, "coordinates equal to the input's, in order")
        dims = [d for d in src.point_format.dimension_names]
        differ = [d for d in dims if not np.array_equal(np.asarray(out[d]), np.asarray(src[d]))]
        check(not differ, f"{len(dims)} original dimensions equal to the input's" + (f" (differ: {differ})" if differ else ""))
    else:
        print(f"info  {n} points (input {inp.suffix}: coordinates not compared)")
    run = Path(a.labelled).resolve().parent.parent
    ids, curves_json = run_curve_ids(run)
    tol = a.tolerance
    if tol is None and curves_json.is_file():
        tol = json.loads(curves_json.read_text())["tolerance"]
    d, cid, edge = np.asarray(out["edge_distance"]), np.asarray(out["curve_id"]), np.asarray(out["edge"])
    if tol is not None:
        check(np.array_equal(edge == 1, d <= tol), f"edge = 1 exactly where edge_distance <= {tol:.6g} ({int((edge == 1).sum())} points)")
    if ids is not None:
        bad = set(np.unique(cid).tolist()) - ids - {-1}
        check(not bad, f"curve_id -1 or one of the run's {len(ids)} curves" + (f" (unknown: {sorted(bad)[:5]})" if bad else ""))
    print(f"info  edge_distance {d.min():.6g} to {d.max():.6g}; {int((cid >= 0).sum())} points with a curve_id")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
