#!/usr/bin/env python3
"""The soak's timeline (bench/soak.sh): lease latency p50 and p99, merged tasks per second, the
coordinator's CPU and resident memory over time, as an SVG image and a JSON summary, and the
"flat" verdict of docs/reliability.md:

  - the coordinator's RSS at the end within 10% of its RSS at minute 2;
  - the lease latency p99 of the last minute within 1.5 times minute 2's.

Minute 2 is [60 s, 120 s) after the load started; the last minute is the 60 s before the run's
end (when the last job ended, or --minutes passed if later). Python's standard library only.

  soak_plot.py --start UNIX --end UNIX --coordinator coord.txt --ticks CLK_TCK
               --load t0.jsonl [t1.jsonl ...] --svg out.svg --summary out.json
               [--title TEXT] [--bin 10]

coord.txt: lines "unix_seconds cpu_ticks rss_kib" (utime + stime of /proc/PID/stat, VmRSS).
Each --load file: soak_load --timeline lines (latency histograms in buckets of 2^(1/16) us).
Exit 0; 1 when the run is not flat (or too short to tell: under 3 minutes).
"""
import argparse
import json
import math
import sys
from collections import defaultdict

BUCKETS_PER_DOUBLING = 16


def bucket_value_us(bucket):
    """A bucket's geometric middle, in microseconds."""
    return 2 ** ((bucket + 0.5) / BUCKETS_PER_DOUBLING)


def percentile(hist, q):
    """The q-quantile (0..1) of a {bucket: count} histogram; None when empty."""
    total = sum(hist.values())
    if total == 0:
        return None
    rank = q * total
    seen = 0
    for bucket in sorted(hist):
        seen += hist[bucket]
        if seen >= rank:
            return bucket_value_us(bucket)
    return bucket_value_us(max(hist))


def read_load(paths):
    """Per interval end (rounded to ms): merged histogram, lease calls, leased, merged."""
    lines = defaultdict(lambda: {"hist": defaultdict(int), "calls": 0, "leased": 0, "merged": 0})
    for path in paths:
        with open(path) as f:
            for n, text in enumerate(f, 1):
                if not text.strip():
                    continue
                try:
                    d = json.loads(text)
                except json.JSONDecodeError as e:
                    sys.exit(f"{path}:{n}: {e}")
                entry = lines[round(d["t"], 3)]
                for bucket, count in d["latency_us_log2x16"].items():
                    entry["hist"][int(bucket)] += count
                entry["calls"] += d["lease_calls"]
                entry["leased"] += d["leased"]
                entry["merged"] += d["merged"]
    return lines


def read_coordinator(path):
    samples = []
    with open(path) as f:
        for text in f:
            parts = text.split()
            if len(parts) == 3:
                samples.append(tuple(float(p) for p in parts))
    return samples


def window_hist(load, lo, hi):
    """The merged latency histogram of the intervals ending in (lo, hi]."""
    hist = defaultdict(int)
    for t, entry in load.items():
        if lo < t <= hi:
            for bucket, count in entry["hist"].items():
                hist[bucket] += count
    return hist


def rss_at(samples, t):
    """The RSS sample (MiB) nearest to time t."""
    best = min(samples, key=lambda s: abs(s[0] - t))
    return best[2] / 1024


def nice_step(span, ticks=5):
    raw = span / ticks
    mag = 10 ** math.floor(math.log10(raw)) if raw > 0 else 1
    for m in (1, 2, 2.5, 5, 10):
        if raw <= m * mag:
            return m * mag
    return 10 * mag


def svg_panel(x0, y0, w, h, minutes, series, ylabel, marks=(), log=False, spans=()):
    """One panel: series = [(label, colour, [(minute, value)...], dashed)], marks = horizontal
    reference lines [(value, colour, label)], spans = shaded time windows [(from, to, label)] in
    minutes; log: a logarithmic value axis (decades). Returns SVG text."""
    values = [v for _, _, pts, _ in series for _, v in pts if v is not None]
    values += [v for v, _, _ in marks]
    if log:
        positive = [v for v in values if v > 0] or [1]
        bottom = 10 ** math.floor(math.log10(min(positive)))
        top = 10 ** math.ceil(math.log10(max(positive) * 1.01))
        if top <= bottom:
            top = bottom * 10
        ticks = [bottom * 10 ** k for k in range(round(math.log10(top / bottom)) + 1)]
    else:
        bottom = 0.0
        top = max(values) * 1.1 if values and max(values) > 0 else 1
        step = nice_step(top)
        top = math.ceil(top / step) * step
        ticks = [k * step for k in range(int(round(top / step)) + 1)]

    def px(m):
        return x0 + w * m / minutes

    def py(v):
        if log:
            v = max(v, bottom)
            return y0 + h - h * math.log10(v / bottom) / math.log10(top / bottom)
        return y0 + h - h * v / top

    out = [f'<rect x="{x0}" y="{y0}" width="{w}" height="{h}" fill="none" stroke="#888"/>']
    for lo, hi, label in spans:
        lo, hi = max(lo, 0), min(hi, minutes)
        if hi > lo:
            out.append(f'<rect x="{px(lo):.1f}" y="{y0}" width="{px(hi) - px(lo):.1f}" '
                       f'height="{h}" fill="#f2f2f2"/>')
            out.append(f'<text x="{(px(lo) + px(hi)) / 2:.1f}" y="{y0 + h - 4}" '
                       f'text-anchor="middle" font-size="10" fill="#777">{label}</text>')
    for v in ticks:
        out.append(f'<line x1="{x0}" x2="{x0 + w}" y1="{py(v):.1f}" y2="{py(v):.1f}" '
                   'stroke="#ddd"/>')
        label = f"{v:g}" if v < 1e4 else f"{v:.3g}"
        out.append(f'<text x="{x0 - 6}" y="{py(v) + 4:.1f}" text-anchor="end" '
                   f'font-size="11">{label}</text>')
    mstep = nice_step(minutes, 10)
    m = 0.0
    while m <= minutes + 1e-9:
        out.append(f'<line x1="{px(m):.1f}" x2="{px(m):.1f}" y1="{y0}" y2="{y0 + h}" '
                   'stroke="#eee"/>')
        out.append(f'<text x="{px(m):.1f}" y="{y0 + h + 14}" text-anchor="middle" '
                   f'font-size="11">{m:g}</text>')
        m += mstep
    out.append(f'<text x="{x0 - 48}" y="{y0 + h / 2}" transform="rotate(-90 {x0 - 48} '
               f'{y0 + h / 2})" text-anchor="middle" font-size="12">{ylabel}</text>')
    for value, colour, label in marks:
        out.append(f'<line x1="{x0}" x2="{x0 + w}" y1="{py(value):.1f}" y2="{py(value):.1f}" '
                   f'stroke="{colour}" stroke-dasharray="2,3"/>')
        out.append(f'<text x="{x0 + w - 4}" y="{py(value) - 3:.1f}" text-anchor="end" '
                   f'font-size="10" fill="{colour}">{label}</text>')
    legend_x = x0 + 8
    for label, colour, pts, dashed in series:
        segments, current = [], []
        for mm, val in pts:
            if val is None:
                if current:
                    segments.append(current)
                current = []
            else:
                current.append(f"{px(mm):.1f},{py(val):.1f}")
        if current:
            segments.append(current)
        dash = ' stroke-dasharray="5,3"' if dashed else ""
        for seg in segments:
            out.append(f'<polyline fill="none" stroke="{colour}" stroke-width="1.5"{dash} '
                       f'points="{" ".join(seg)}"/>')
        out.append(f'<line x1="{legend_x}" x2="{legend_x + 18}" y1="{y0 + 12}" y2="{y0 + 12}" '
                   f'stroke="{colour}" stroke-width="2"{dash}/>')
        out.append(f'<text x="{legend_x + 22}" y="{y0 + 16}" font-size="11">{label}</text>')
        legend_x += 30 + 7 * len(label)
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--start", type=float, required=True)
    ap.add_argument("--end", type=float, required=True)
    ap.add_argument("--coordinator", required=True)
    ap.add_argument("--ticks", type=float, default=100)
    ap.add_argument("--load", nargs="+", required=True)
    ap.add_argument("--svg", required=True)
    ap.add_argument("--summary", required=True)
    ap.add_argument("--title", default="rayfarm soak")
    ap.add_argument("--bin", type=float, default=10, help="seconds per plotted point")
    a = ap.parse_args()

    load = read_load(a.load)
    coord = [s for s in read_coordinator(a.coordinator) if a.start - 10 <= s[0] <= a.end + 10]
    if len(coord) < 2 or not load:
        sys.exit("soak_plot: no samples")
    length = a.end - a.start
    minutes = max(1.0, math.ceil(length / 60))

    # Per bin: latency percentiles, merged tasks/s, CPU %, RSS.
    lat50, lat99, merged, cpu, rss = [], [], [], [], []
    nbins = int(math.ceil(length / a.bin))
    for i in range(nbins):
        lo, hi = a.start + i * a.bin, a.start + (i + 1) * a.bin
        mid = (i + 0.5) * a.bin / 60
        hist = window_hist(load, lo, hi)
        p50, p99 = percentile(hist, 0.5), percentile(hist, 0.99)
        lat50.append((mid, p50 / 1000 if p50 else None))
        lat99.append((mid, p99 / 1000 if p99 else None))
        n = sum(e["merged"] for t, e in load.items() if lo < t <= hi)
        merged.append((mid, n / a.bin))
    for (t0, c0, _), (t1, c1, r1) in zip(coord, coord[1:]):
        if t1 > t0:
            mid = ((t0 + t1) / 2 - a.start) / 60
            cpu.append((mid, 100 * (c1 - c0) / a.ticks / (t1 - t0)))
            rss.append(((t1 - a.start) / 60, r1 / 1024))

    # The verdict.
    summary = {"seconds": round(length, 1)}
    flat = True
    reasons = []
    if length < 180:
        flat = False
        reasons.append(f"run of {length:.0f} s: under 3 minutes, too short to tell")
    m2 = window_hist(load, a.start + 60, a.start + 120)
    last = window_hist(load, a.end - 60, a.end)
    p99_m2, p99_last = percentile(m2, 0.99), percentile(last, 0.99)
    in_run = [s for s in coord if s[0] <= a.end]
    rss_m2 = rss_at(coord, a.start + 120)
    rss_end = in_run[-1][2] / 1024 if in_run else rss_at(coord, a.end)
    summary.update({
        "rss_mib_minute_2": round(rss_m2, 1),
        "rss_mib_end": round(rss_end, 1),
        "rss_mib_peak": round(max(s[2] for s in in_run) / 1024, 1) if in_run else None,
        "lease_p50_ms_minute_2": round(percentile(m2, 0.5) / 1000, 3) if m2 else None,
        "lease_p99_ms_minute_2": round(p99_m2 / 1000, 3) if p99_m2 else None,
        "lease_p50_ms_last_minute": round(percentile(last, 0.5) / 1000, 3) if last else None,
        "lease_p99_ms_last_minute": round(p99_last / 1000, 3) if p99_last else None,
        "lease_calls": sum(e["calls"] for e in load.values()),
        "tasks_leased": sum(e["leased"] for e in load.values()),
        "tasks_merged": sum(e["merged"] for e in load.values()),
        "coordinator_cpu_seconds": round((in_run[-1][1] - coord[0][1]) / a.ticks, 1)
        if in_run else None,
    })
    if rss_end > 1.10 * rss_m2:
        flat = False
        reasons.append(f"RSS at the end {rss_end:.0f} MiB > 1.10 x minute 2's {rss_m2:.0f} MiB")
    if p99_m2 is None or p99_last is None:
        flat = False
        reasons.append("no lease answered in minute 2 or in the last minute")
    elif p99_last > 1.5 * p99_m2:
        flat = False
        reasons.append(f"last-minute lease p99 {p99_last / 1000:.2f} ms > 1.5 x minute 2's "
                       f"{p99_m2 / 1000:.2f} ms")
    summary["flat"] = flat
    summary["not_flat_because"] = reasons

    # The image: four panels sharing the time axis.
    w, h, left, top_margin, gap = 760, 150, 80, 40, 40
    windows = [(1, 2, "minute 2"), (length / 60 - 1, length / 60, "last minute")]
    panels = [
        (svg_panel(left, 0, w, h, minutes, [("p50", "#1f77b4", lat50, False),
                                            ("p99", "#d62728", lat99, False)],
                   "lease latency (ms, log)",
                   [(p99_m2 / 1000 * 1.5, "#d62728", "1.5 x minute 2's p99")] if p99_m2 else [],
                   log=True, spans=windows)),
        (svg_panel(left, 0, w, h, minutes, [("merged tasks/s", "#2ca02c", merged, False)],
                   "tasks/s")),
        (svg_panel(left, 0, w, h, minutes, [("coordinator CPU", "#9467bd", cpu, False)],
                   "CPU (% of a core)")),
        (svg_panel(left, 0, w, h, minutes, [("coordinator RSS", "#8c564b", rss, False)],
                   "RSS (MiB)",
                   [(rss_m2 * 1.1, "#8c564b", "1.1 x RSS at minute 2")], spans=windows)),
    ]
    height = top_margin + len(panels) * (h + gap) + 20
    body = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{left + w + 20}" height="{height}" '
            f'font-family="sans-serif">',
            f'<rect width="100%" height="100%" fill="white"/>',
            f'<text x="{left}" y="20" font-size="14">{a.title}</text>']
    for i, panel in enumerate(panels):
        body.append(f'<g transform="translate(0 {top_margin + i * (h + gap)})">{panel}</g>')
    body.append(f'<text x="{left + w / 2}" y="{height - 8}" text-anchor="middle" '
                'font-size="12">minutes since the load started</text>')
    body.append("</svg>")
    with open(a.svg, "w") as f:
        f.write("\n".join(body) + "\n")
    with open(a.summary, "w") as f:
        json.dump(summary, f, indent=1)
        f.write("\n")
    print(json.dumps(summary))
    return 0 if flat else 1


if __name__ == "__main__":
    sys.exit(main())
