#!/usr/bin/env python3
"""The server grid's medians: reads the gmr-load --json results that
bench/server/run.sh wrote (RUNS_DIR/<transport>-<mode>-<subscribers>-<repeat>.json)
and writes one CSV row per point and a PNG (gnuplot).

    summarize.py RUNS_DIR OUT.csv OUT.png
"""
import csv
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile


def load(runs_dir):
    points = {}
    for name in sorted(os.listdir(runs_dir)):
        if not name.endswith(".json"):
            continue
        transport, mode, subscribers, _repeat = name[:-5].split("-")
        with open(os.path.join(runs_dir, name)) as f:
            r = json.load(f)
        points.setdefault((transport, mode, int(subscribers)), []).append(r)
    return points


def floors(runs_dir, sub="", field=lambda r: r["ns_per_frame"]):
    """gmr-floor's median `field` (by default its ns per frame) by (transport,
    subscribers): its runs in runs/floor, or with sub="phased" those sent in
    phases (run.sh, PHASES). Runs without the field (an older gmr-floor's) are
    left out."""
    found = {}
    floor_dir = os.path.join(runs_dir, "floor", sub)
    if os.path.isdir(floor_dir):
        for name in sorted(os.listdir(floor_dir)):
            if name.endswith(".json"):
                transport, subscribers, _repeat = name[:-5].split("-")
                with open(os.path.join(floor_dir, name)) as f:
                    try:
                        value = field(json.load(f))
                    except KeyError:
                        continue
                found.setdefault((transport, int(subscribers)), []).append(value)
    return {k: statistics.median(v) for k, v in found.items()}


def row(key, runs, floor_ns=None, phased_ns=None, floor_p99=None):
    transport, mode, subscribers = key
    med = lambda f: statistics.median(f(r) for r in runs)
    window = lambda r: r["seconds"] or 1.0
    lost = lambda r: 100.0 * r["gaps"] / max(1, r["gaps"] + r["frames"])
    server_cores = lambda r: r.get("server_cpu_seconds", float("nan")) / window(r)
    server_ns = lambda r: 1e9 * r.get("server_cpu_seconds", float("nan")) / max(1, r["frames"])
    load_cores = lambda r: (r["cpu_user_seconds"] + r["cpu_system_seconds"]) / window(r)
    return {
        "transport": transport,
        "stream": mode,
        "subscribers": subscribers,
        "expected_fps": round(med(lambda r: r["expected_per_second"])),
        "delivered_fps": round(med(lambda r: r["delivered_per_second"])),
        "lost_pct": round(med(lost), 3),
        "p50_ms": round(med(lambda r: r["latency_ms"]["p50"]), 3),
        "p99_ms": round(med(lambda r: r["latency_ms"]["p99"]), 3),
        "p999_ms": round(med(lambda r: r["latency_ms"]["p99.9"]), 3),
        "max_ms": round(med(lambda r: r["latency_ms"]["max"]), 3),
        "server_cores": round(med(server_cores), 3),
        "server_ns_per_frame": round(med(server_ns)),
        "load_cores": round(med(load_cores), 3),
        "floor_ns_per_frame": round(floor_ns) if floor_ns else "",
        "floor_ratio": round(med(server_ns) / floor_ns, 2) if floor_ns else "",
        # The p99 latency of the floor's frames (each burst's last waits for the others).
        "floor_p99_ms": round(floor_p99, 3) if floor_p99 else "",
        # Own streams only: the floor whose frames leave in phases, as theirs do.
        "phased_floor_ns_per_frame": round(phased_ns) if phased_ns and mode == "own" else "",
        "phased_floor_ratio": round(med(server_ns) / phased_ns, 2) if phased_ns and mode == "own" else "",
        "setup_s": round(med(lambda r: r["setup_seconds"]), 2),
        "repeats": len(runs),
    }


def plot(rows, png):
    if shutil.which("gnuplot") is None:
        print("summarize: gnuplot not found (apt-get install gnuplot-nox): no plot", file=sys.stderr)
        return
    with tempfile.TemporaryDirectory() as tmp:
        series = []
        for transport in ("tcp", "udp"):
            for mode in ("own", "shared"):
                pts = sorted((r for r in rows if r["transport"] == transport and r["stream"] == mode),
                             key=lambda r: r["subscribers"])
                if not pts:
                    continue
                path = os.path.join(tmp, f"{transport}-{mode}.dat")
                with open(path, "w") as f:
                    for r in pts:
                        f.write(f'{r["subscribers"]} {r["delivered_fps"]} {r["expected_fps"]} {r["p99_ms"]}\n')
                series.append((path, f"{transport.upper()} {mode}"))
        if not series:
            return
        delivered = ", ".join(f"'{p}' using 1:2 with linespoints lw 2 title '{t}'" for p, t in series)
        expected = f"'{series[0][0]}' using 1:3 with lines dt 2 lc 'gray' title 'due (120 Hz each)'"
        p99 = ", ".join(f"'{p}' using 1:4 with linespoints lw 2 title '{t}'" for p, t in series)
        partial = png + ".partial"
        script = f"""set terminal pngcairo size 1200,520 font ',11'
set output '{partial}'
set multiplot layout 1,2 title 'gmr-server on one core, gmr-load on the other (medians)'
set logscale xy
set grid
set key top left
set xlabel 'subscribers'
set ylabel 'frames/s delivered'
plot {delivered}, {expected}
set ylabel 'p99 latency (ms)'
plot {p99}
unset multiplot
"""
        subprocess.run(["gnuplot"], input=script, text=True, check=True)
        os.replace(partial, png)


def main():
    runs_dir, out_csv, out_png = sys.argv[1:4]
    points = load(runs_dir)
    if not points:
        sys.exit(f"summarize: no results in {runs_dir}")
    floor, phased = floors(runs_dir), floors(runs_dir, "phased")
    floor_p99 = floors(runs_dir, field=lambda r: r["latency_ms"]["p99"])
    rows = [row(k, v, floor.get((k[0], k[2])), phased.get((k[0], k[2])), floor_p99.get((k[0], k[2])))
            for k, v in sorted(points.items())]
    partial = out_csv + ".partial"
    with open(partial, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    os.replace(partial, out_csv)
    plot(rows, out_png)
    for r in rows:
        print(f'{r["transport"]:3} {r["stream"]:6} {r["subscribers"]:6}: {r["delivered_fps"]:>9} of {r["expected_fps"]:>9} '
              f'frames/s, lost {r["lost_pct"]}%, p99 {r["p99_ms"]} ms, p99.9 {r["p999_ms"]} ms, '
              f'server {r["server_ns_per_frame"]} ns/frame'
              + (f' ({r["floor_ratio"]}x the floor\'s {r["floor_ns_per_frame"]})' if r["floor_ratio"] != "" else "")
              + (f' ({r["phased_floor_ratio"]}x the phased floor\'s {r["phased_floor_ns_per_frame"]})'
                 if r["phased_floor_ratio"] != "" else "")
              + f', load {r["load_cores"]} cores')
    print(f"wrote {out_csv} and {out_png}")


if __name__ == "__main__":
    main()
