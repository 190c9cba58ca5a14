#!/usr/bin/env python3
"""Typed curves on a corpus of machined parts: the share of truth edges recovered as one piece of
the right type (a line between the edge's ends; a circle, or an arc between the edge's ends, of
its centre, axis and radius; a spline for a free-form edge: an ellipse, a B-spline or other), the
circles' radius error, and the pieces written against the truth's edge count.

A corpus is a folder of NAME.off meshes with NAME.truth.obj and NAME.json (its `edges` give
each truth edge's `kind`, line, circle or other, and a circle's centre, axis and radius), as
`../shared/data/cad/` or the output of `../shared/tools/cad_corpus.py`. Clouds are those of
scripts/corpus.py (the same cache folder).

    scripts/typed-curves.py [CORPUS ...] [--work DIR] [--levels "0 k2"] [--bin BIN] [--tol 0.01]

An edge counts as recovered when one piece of its kind holds all of it within TOL dB: a line
segment within TOL of the edge's ends and middle; a circle (for an open circular edge, an arc or a
circle) whose centre and radius are within TOL of the edge's, whose axis is within 5 degrees of
it, and whose sweep holds the edge's points; a spline within TOL of nine points along the edge. A piece may run on past the edge's ends: a B-rep
splits a rim or a line at vertices the surface does not show.
"""
import json
import math
import shutil
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import corpus  # noqa: E402  (the clouds and their cache)


def truth_lines(obj):
    verts, lines = [], []
    for line in Path(obj).read_text().splitlines():
        s = line.split()
        if s and s[0] == "v":
            verts.append(tuple(map(float, s[1:4])))
        elif s and s[0] == "l":
            lines.append([verts[int(x.split("/")[0]) - 1] for x in s[1:]])
    return lines


def dist(a, b):
    return math.dist(a, b)


def off_segment(p, a, b):
    ab = [y - x for x, y in zip(a, b)]
    t = max(0.0, min(1.0, sum((p[i] - a[i]) * ab[i] for i in range(3)) / max(sum(x * x for x in ab), 1e-300)))
    return dist(p, [a[i] + t * ab[i] for i in range(3)])


def on_arc(p, piece, tol):
    """True if p lies within tol of the arc's circle and within its sweep."""
    c, ax, r = piece["centre"], piece["axis"], piece["radius"]
    n = math.hypot(*ax)
    ax = [x / n for x in ax]
    d = [p[i] - c[i] for i in range(3)]
    h = sum(d[i] * ax[i] for i in range(3))
    radial = [d[i] - h * ax[i] for i in range(3)]
    if math.hypot(math.hypot(*radial) - r, h) > tol:
        return False
    if piece["kind"] == "circle":
        return True
    s = [piece["start"][i] - c[i] for i in range(3)]
    cross = [s[1] * radial[2] - s[2] * radial[1], s[2] * radial[0] - s[0] * radial[2], s[0] * radial[1] - s[1] * radial[0]]
    ang = math.atan2(sum(cross[i] * ax[i] for i in range(3)), sum(s[i] * radial[i] for i in range(3))) % (2 * math.pi)
    slack = tol / max(r, 1e-300)
    return ang <= math.radians(piece["sweep_deg"]) + slack or ang >= 2 * math.pi - slack


def de_boor(degree, knots, ctrl, t):
    k = max(j for j in range(degree, len(ctrl)) if knots[j] <= t)
    d = [list(ctrl[j + k - degree]) for j in range(degree + 1)]
    for r in range(1, degree + 1):
        for j in range(degree, r - 1, -1):
            lo, hi = knots[j + k - degree], knots[j + 1 + k - r]
            a = (t - lo) / (hi - lo) if hi > lo else 0.0
            d[j] = [(1 - a) * x + a * y for x, y in zip(d[j - 1], d[j])]
    return d[degree]


def drawn(piece, n=400):
    """A spline piece as n + 1 points from its start to its end."""
    if "_drawn" not in piece:
        deg, knots, ctrl = piece["degree"], piece["knots"], piece["control_points"]
        a, b = knots[deg], knots[len(ctrl)]
        piece["_drawn"] = [de_boor(deg, knots, ctrl, a + (b - a) * i / n) for i in range(n + 1)]
    return piece["_drawn"]


FREE_FORM = ("ellipse", "bspline", "other")


def matches(edge, poly, piece, tol):
    """A piece of the edge's kind that holds the whole edge within tol (it may run on past the
    edge's ends, where the part has a B-rep vertex that the scan does not show)."""
    if edge["kind"] == "line" and piece["kind"] == "line":
        return all(off_segment(p, piece["start"], piece["end"]) <= tol for p in (poly[0], poly[len(poly) // 2], poly[-1]))
    # (A truth circle that is not closed is an arc, held by an arc or a circle; a closed one
    # only by a circle.)
    if edge["kind"] in FREE_FORM and piece["kind"] == "spline":
        d = drawn(piece)
        near = lambda p: min(off_segment(p, d[i], d[i + 1]) for i in range(len(d) - 1)) <= tol
        return all(near(poly[round(i * (len(poly) - 1) / 8)]) for i in range(9))
    if edge["kind"] == "circle" and piece["kind"] in (("circle",) if edge["closed"] else ("arc", "circle")):
        ax, pax = edge["axis"], piece["axis"]
        cos = abs(sum(x * y for x, y in zip(ax, pax))) / (math.hypot(*ax) * math.hypot(*pax))
        return (dist(edge["center"], piece["centre"]) <= tol and abs(edge["radius"] - piece["radius"]) <= tol
                and cos >= math.cos(math.radians(5)) and all(on_arc(p, piece, tol) for p in poly[::max(1, len(poly) // 8)] + [poly[-1]]))
    return False


def main():
    ap = corpus.arguments(__doc__, "0 k2")
    ap.add_argument("--tol", type=float, default=0.01, help="match tolerance, dB")
    args, extra = ap.parse_known_args()
    extra = [a for a in extra if a != "--"]
    binary, work = corpus.setup(args.bin, args.work)
    parts = [off.resolve() for c in args.corpus for off in sorted(Path(c).glob("*.off"))
             if off.with_suffix(".json").exists() and off.with_suffix("").with_suffix(".truth.obj").exists()]
    if not parts:
        sys.exit(f"typed-curves.py: no NAME.off with NAME.json and NAME.truth.obj in {args.corpus}")
    print(f"{len(parts)} parts, {args.points} points; edges recovered as one piece of their type within {args.tol} dB")
    print()
    print("| noise | lines | circles and arcs | free-form as splines | all typed edges | circle radius error, median (share of r) | pieces / truth edges | pieces by kind |")
    print("|---|---|---|---|---|---|---|---|")
    for level in args.levels.split():
        found = {"line": [0, 0], "circle": [0, 0], "free": [0, 0]}
        kinds = {}
        radius_errors, piece_counts, edge_counts = [], 0, 0
        for off in parts:
            name = f"{off.parent.name}_{off.stem}"
            cloud = corpus.sampled(binary, work, off, level, args.points)
            out = work / f"typed_{name}_{level}"
            shutil.rmtree(out, ignore_errors=True)
            subprocess.run([str(binary), "extract", str(cloud), "-o", str(out), "-q", "--format", "obj,json"] + extra,
                           check=True)
            pieces = json.loads((out / "curves.json").read_text())["pieces"]
            shutil.rmtree(out, ignore_errors=True)
            meta = json.loads(off.with_suffix(".json").read_text())
            tol = args.tol * meta["bbox_diag"]
            lines = truth_lines(off.with_suffix("").with_suffix(".truth.obj"))
            piece_counts += len(pieces)
            edge_counts += len(meta["edges"])
            for p in pieces:
                kinds[p["kind"]] = kinds.get(p["kind"], 0) + 1
            part_found = {"line": [0, 0], "circle": [0, 0], "free": [0, 0]}
            for edge in meta["edges"]:
                group = "free" if edge["kind"] in FREE_FORM else edge["kind"]
                if group not in found:
                    continue
                poly = lines[edge["obj_line"] - 1]
                hit = [p for p in pieces if matches(edge, poly, p, tol)]
                part_found[group][1] += 1
                if hit:
                    part_found[group][0] += 1
                    if edge["kind"] == "circle":
                        best = min(hit, key=lambda p: abs(p["radius"] - edge["radius"]))
                        radius_errors.append(abs(best["radius"] - edge["radius"]) / edge["radius"])
            for k in found:
                found[k][0] += part_found[k][0]
                found[k][1] += part_found[k][1]
            print(f"  {name} {level}: lines {part_found['line'][0]}/{part_found['line'][1]}, circles "
                  f"{part_found['circle'][0]}/{part_found['circle'][1]}, free-form "
                  f"{part_found['free'][0]}/{part_found['free'][1]}, {len(pieces)} pieces for "
                  f"{len(meta['edges'])} edges", file=sys.stderr, flush=True)
        share = lambda k: f"{found[k][0] / found[k][1]:.3f} ({found[k][0]} of {found[k][1]})" if found[k][1] else "-"
        both = [found["line"][0] + found["circle"][0], found["line"][1] + found["circle"][1]]
        label = f"{level[1:]} spacings" if level.startswith("k") else ("none" if level == "0" else f"{level} dB")
        rerr = f"{statistics.median(radius_errors):.4f}" if radius_errors else "-"
        by_kind = ", ".join(f"{kinds[k]} {k}" for k in sorted(kinds))
        print(f"| {label} | {share('line')} | {share('circle')} | {share('free')} | {both[0] / max(both[1], 1):.3f} | {rerr} | "
              f"{piece_counts / max(edge_counts, 1):.2f} | {by_kind} |")


if __name__ == "__main__":
    main()
