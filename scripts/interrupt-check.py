#!/usr/bin/env python3
"""SIGTERM (or SIGINT) a run at many moments and measure how long it takes to stop.

    scripts/interrupt-check.py CLOUD [--bin BIN ...] [--signals 24] [--work DIR] [--resume]

For each binary (several are run in turn at each moment, so that they share the machine's
load), an uninterrupted run first gives the stages' timeline and the reference outputs; then
each of --signals fresh runs is sent the signal at an evenly spread moment of that timeline
(from 2 % to 98 % of the run), and the time from the signal to the process' exit is taken.
The stage a signal landed in is the last progress line the run printed before it
("after X" between a stage's end and the next one's start: the statistics probe, the survey,
the writers). A run that was signalled must exit 130 saying "interrupted"; with --resume, each
is then run again to its end and its curves compared byte for byte with the reference.

Prints one line a signal, then per binary and stage the count, median and max latency.
Exit status 1 if a signalled run exited otherwise than 130/"interrupted" (a run that had
finished before the signal arrived is counted apart), or if a resumed run's curves differ.
"""
import argparse
import os
import shutil
import signal
import statistics
import subprocess
import sys
import threading
import time

OUTPUTS = ["curves.obj", "curves.ply", "curves.geojson", "curves.json"]


def run(binary, cloud, out, extra, sig_at=None, sig=signal.SIGTERM):
    """Runs one extraction; returns (exit code, stderr lines with their times, signal time,
    exit time), times from the start."""
    cmd = [binary, "extract", cloud, "-o", out, "--memory", "256M"] + extra
    env = dict(os.environ, NO_COLOR="1")
    t0 = time.monotonic()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, text=True)
    lines = []

    def read():
        for line in p.stderr:
            lines.append((time.monotonic() - t0, line.rstrip("\n")))

    reader = threading.Thread(target=read)
    reader.start()
    sent = None
    if sig_at is not None:
        while time.monotonic() - t0 < sig_at and p.poll() is None:
            time.sleep(min(0.005, max(0.0, sig_at - (time.monotonic() - t0))))
        if p.poll() is None:
            p.send_signal(sig)
            sent = time.monotonic() - t0
    rc = p.wait()
    ended = time.monotonic() - t0
    reader.join()
    return rc, lines, sent, ended


def progress(lines):
    """The progress lines of a run's stderr as (time, stage name, what it says)."""
    for at, line in lines:
        if not line.startswith("crease: "):
            continue
        parts = line[len("crease: "):].split(": ", 1)
        if len(parts) == 2:
            yield at, parts[0], parts[1]


def stage_at(lines, t):
    """The stage that a moment `t` of a run falls in, from its progress lines."""
    stage = "start"
    for at, name, what in progress(lines):
        if at > t:
            break
        stage = f"after {name}" if what.startswith("done") else name
    return stage


def segments(lines, total):
    """The run's timeline as (name, start, end): each stage, and the gaps between a stage's end
    and the next one's start, from the progress lines that begin or end a stage."""
    events = [(0.0, "start")]
    for at, name, what in progress(lines):
        if what.startswith("done"):
            events.append((at, f"after {name}"))
        elif "/" not in what.split(" ")[0]:
            events.append((at, name))
    events.append((total, "end"))
    return [(n, t, u) for (t, n), (u, _) in zip(events, events[1:])]


def moments(lines, total, n):
    """About `n` moments spread over the timeline, as (segment number, share of it): at least
    two in each stage or gap of 0.2 s or more and one in each shorter gap, the rest by
    duration."""
    segs = segments(lines, total)
    out = []
    for i, (_, t, u) in enumerate(segs):
        d = u - t
        k = max(2, round(n * d / total)) if d >= 0.2 else (1 if d > 0.01 else 0)
        out.extend((i, (j + 0.5) / k) for j in range(k))
    return out


def at_share(lines, total, seg, share):
    segs = segments(lines, total)
    _, t, u = segs[min(seg, len(segs) - 1)]
    return t + share * (u - t)


def same_curves(a, b):
    return all(open(os.path.join(a, f), "rb").read() == open(os.path.join(b, f), "rb").read() for f in OUTPUTS if os.path.exists(os.path.join(a, f)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cloud")
    ap.add_argument("--bin", action="append", help="binaries to compare (default: target/release/crease)")
    ap.add_argument("--signals", type=int, default=24)
    ap.add_argument("--work", default=None)
    ap.add_argument("--resume", action="store_true", help="resume each signalled run and compare its curves")
    ap.add_argument("--sigint", action="store_true", help="send SIGINT (Ctrl-C) instead of SIGTERM")
    ap.add_argument("--extra", default="--label-points", help="further extract options (default: --label-points, so the label pass is covered)")
    a = ap.parse_args()
    bins = [os.path.realpath(b) for b in (a.bin or ["target/release/crease"])]
    work = a.work or os.path.join("/tmp", f"interrupt-check-{os.getpid()}")
    os.makedirs(work, exist_ok=True)
    extra = a.extra.split()
    sig = signal.SIGINT if a.sigint else signal.SIGTERM
    ref = {}
    for i, b in enumerate(bins):
        out = os.path.join(work, f"ref{i}")
        shutil.rmtree(out, ignore_errors=True)
        rc, lines, _, ended = run(b, a.cloud, out, extra)
        if rc != 0:
            sys.exit(f"{b}: the uninterrupted run exited {rc}: {lines[-1][1] if lines else ''}")
        ref[b] = (out, lines, ended)
        print(f"{b}: uninterrupted run {ended:.1f} s; stages: " + ", ".join(f"{l.split(': ')[1]} at {t:.1f}" for t, l in lines if ": " in l and not l.split(": ", 2)[-1].startswith("done") and l.startswith("crease: ")), flush=True)
    bad = 0
    rows = {b: [] for b in bins}
    for k, (seg, share) in enumerate(moments(ref[bins[0]][1], ref[bins[0]][2], a.signals)):
        for i, b in enumerate(bins):
            out = os.path.join(work, f"sig{i}")
            shutil.rmtree(out, ignore_errors=True)
            # (The same share of the same stage in each binary's own timeline.)
            at = at_share(ref[b][1], ref[b][2], seg, share)
            rc, lines, sent, ended = run(b, a.cloud, out, extra, sig_at=at, sig=sig)
            if sent is None:
                print(f"{os.path.basename(b)} k={k}: finished ({rc}) before the signal at {at:.2f} s", flush=True)
                continue
            last = lines[-1][1] if lines else ""
            stage = stage_at(lines, sent)
            latency = ended - sent
            ok = rc == 130 and "interrupted" in last
            # (A run that had written its outputs when the signal came may exit 0.)
            if rc == 0 and not any("interrupted" in l for _, l in lines):
                ok, stage = True, stage + " (finished)"
            note = ""
            if not ok:
                bad += 1
                note = "  <-- not interrupted cleanly"
            if a.resume and rc == 130:
                rc2, lines2, _, _ = run(b, a.cloud, out, extra)
                same = rc2 == 0 and same_curves(ref[b][0], out)
                note += f"  resumed: {'same bytes' if same else f'DIFFERENT (exit {rc2})'}"
                if not same:
                    bad += 1
            rows[b].append((stage, latency))
            print(f"{os.path.basename(b)} k={k} signal at {sent:6.2f} s in {stage:<18} exit {rc} after {latency:5.3f} s: {last}{note}", flush=True)
    for b in bins:
        print(f"\n{b}")
        by = {}
        for stage, lat in rows[b]:
            by.setdefault(stage, []).append(lat)
        print(f"  {'stage':<24}{'n':>4}{'median s':>10}{'max s':>8}")
        for stage, lats in sorted(by.items(), key=lambda kv: -max(kv[1])):
            print(f"  {stage:<24}{len(lats):>4}{statistics.median(lats):>10.3f}{max(lats):>8.3f}")
        all_l = [l for _, l in rows[b]]
        if all_l:
            print(f"  {'all':<24}{len(all_l):>4}{statistics.median(all_l):>10.3f}{max(all_l):>8.3f}")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
