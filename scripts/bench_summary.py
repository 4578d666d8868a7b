#!/usr/bin/env python3
"""The table of scripts/bench.sh from its output folder (runs.tsv, machine.txt and each run's
folder): one row per build and case, the median over that build's rounds, then, with two builds,
the ratios A / B of those medians.

Columns: frames/s (frames over the command's wall time), SfM ms per frame in detect (on the SfM
thread; "detect ahead": on the prefetch thread, outside the SfM's time), match, resect,
bundle adjustment (local) and the rest of the SfM's time (other: triangulation, the map-point
search, shown apart when stats/sfm_stages.csv has it, map upkeep, loading, loop closures, the
final adjustment), the SfM's time waiting on a full surface queue,
surface ms per keyframe (median, p95, flatness of scripts/surface_bench_summary.py), peak RSS (MB
and MB per 1000 frames), and with --eval the ATE (RMSE of the keyframe centres after the
similarity registration, cm).

usage: bench_summary.py OUT
"""
import csv
import json
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import surface_bench_summary  # noqa: E402

COLUMNS = [  # key, heading, format, lower is better (None: no ratio)
    ("fps", "frames/s", "{:.2f}", False),
    ("detect", "detect", "{:.1f}", True),
    ("detect_ahead", "detect ahead", "{:.1f}", True),
    ("match", "match", "{:.1f}", True),
    ("resect", "resect", "{:.1f}", True),
    ("ba", "BA", "{:.1f}", True),
    ("other", "other", "{:.1f}", True),
    ("map_search", "of which map search", "{:.1f}", True),
    ("queue", "queue wait", "{:.1f}", True),
    ("sfm_total", "SfM ms/frame", "{:.1f}", True),
    ("surf_median", "surface ms/kf median", "{:.1f}", True),
    ("surf_p95", "p95", "{:.1f}", True),
    ("surf_flat", "flatness", "{:.2f}", True),
    ("rss_mb", "peak RSS MB", "{:.0f}", True),
    ("rss_per_1000", "MB / 1000 frames", "{:.0f}", True),
    ("ate_cm", "ATE cm", "{:.2f}", True),
    ("keyframes", "keyframes", "{:.0f}", None),
    ("wall", "wall s", "{:.1f}", True),
]


def read_name_values(path, key, value):
    if not os.path.exists(path):
        return {}
    return {r[key]: float(r[value]) for r in csv.DictReader(open(path))}


def run_figures(run):
    folder = run["folder"]
    fig = {"wall": float(run["wall_s"]) if run["wall_s"] else None}
    if run["max_rss_kb"]:
        fig["rss_mb"] = float(run["max_rss_kb"]) / 1024.0
    stats = os.path.join(folder, "stats")
    frames = None
    summary = read_name_values(os.path.join(stats, "sfm_summary.csv"), "name", "value")
    if "frames" in summary:
        frames = summary["frames"]
        fig["keyframes"] = summary.get("keyframes")
    stages = read_name_values(os.path.join(stats, "sfm_stages.csv"), "stage", "ms_per_frame")
    if stages:
        for key, stage in [("detect", "detect"), ("match", "match"), ("resect", "resect"),
                           ("ba", "bundle_adjustment"), ("queue", "queue_wait")]:
            fig[key] = stages.get(stage, 0.0)
        if "detect_ahead" in stages:  # a row since detection moved to the prefetch thread
            fig["detect_ahead"] = stages["detect_ahead"]
        if "map_search" in stages:  # a row since the bench was written
            fig["map_search"] = stages["map_search"]
        fig["sfm_total"] = stages.get("total", 0.0)
        fig["other"] = fig["sfm_total"] - sum(fig[k] for k in ("detect", "match", "resect", "ba",
                                                                "queue"))
    keyframes_csv = os.path.join(stats, "keyframes.csv")
    if os.path.exists(keyframes_csv):
        t = surface_bench_summary.timing_summary(folder)
        if t["incremental"]:
            fig["surf_median"] = t["total_median"]
            fig["surf_p95"] = t["total_p95"]
            fig["surf_flat"] = t["total_flatness"]
        if frames is None:  # surface --from-gt: one row per keyframe
            fig["keyframes"] = len(t["rows"])
    eval_json = os.path.join(folder, "report", "eval.json")
    if os.path.exists(eval_json):
        poses = json.load(open(eval_json)).get("poses", {})
        if "ate_translation_m" in poses:
            fig["ate_cm"] = 100.0 * poses["ate_translation_m"]["rmse"]
    if frames and fig["wall"]:
        fig["fps"] = frames / fig["wall"]
        if "rss_mb" in fig:
            fig["rss_per_1000"] = fig["rss_mb"] * 1000.0 / frames
    return {k: v for k, v in fig.items() if v is not None}


def median_figures(figure_list):
    keys = {k for f in figure_list for k in f}
    return {k: statistics.median(f[k] for f in figure_list if k in f) for k in keys}


def table(headings, rows):
    lines = ["| " + " | ".join(headings) + " |", "|" + "---|" * len(headings)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def main():
    out = sys.argv[1]
    runs = list(csv.DictReader(open(os.path.join(out, "runs.tsv")), delimiter="\t"))
    machine = {}
    for line in open(os.path.join(out, "machine.txt")):
        if "=" in line:
            k, v = line.rstrip("\n").split("=", 1)
            machine[k] = v
    labels = sorted({r["label"] for r in runs})
    cases = list(dict.fromkeys(r["case"] for r in runs))
    build_of = {r["label"]: r["build"] for r in runs}
    print(f"machine: {machine.get('cpu', '?')}, {machine.get('nproc', '?')} cores, load average "
          f"{machine.get('load_start', '?')} at the start, {machine.get('load_end', '?')} at the "
          f"end; {machine.get('date', '')}")
    for label in labels:
        b = build_of[label]
        print(f"{label}: {b} at {machine.get('build:' + b, '?')}")
    drives = dict.fromkeys(f"{r['case']}: {r['drive']}" for r in runs)
    print("drives: " + "; ".join(drives))
    failed = [r for r in runs if r["exit"] != "0"]
    for r in failed:
        print(f"FAILED: {r['label']} {r['case']} round {r['round']} exit {r['exit']} "
              f"({r['folder']}.log); left out of the medians")
    rounds = max(int(r["round"]) for r in runs)
    print(f"medians over {rounds} round(s)" +
          (", alternated A, B, A, B" if len(labels) > 1 else "") + "\n")

    medians = {}
    for c in cases:
        for label in labels:
            figs = [run_figures(r) for r in runs
                    if r["case"] == c and r["label"] == label and r["exit"] == "0"]
            if figs:
                medians[(c, label)] = median_figures(figs)
    used = [col for col in COLUMNS if any(col[0] in m for m in medians.values())]
    rows = []
    for c in cases:
        for label in labels:
            m = medians.get((c, label), {})
            rows.append([c, label] + [fmt.format(m[k]) if k in m else "" for k, _, fmt, _ in used])
    print(table(["case", "build"] + [h for _, h, _, _ in used], rows))
    if len(labels) == 2:
        a, b = labels
        print(f"\nratios {a} / {b} (frames/s above 1 and times below 1: {a} is faster)\n")
        rows = []
        for c in cases:
            ma, mb = medians.get((c, a), {}), medians.get((c, b), {})
            cells = []
            for k, _, _, lower_is_better in used:
                if lower_is_better is not None and k in ma and k in mb and mb[k] > 0:
                    cells.append(f"{ma[k] / mb[k]:.2f}")
                else:
                    cells.append("")
            rows.append([c, f"{a}/{b}"] + cells)
        print(table(["case", ""] + [h for _, h, _, _ in used], rows))


if __name__ == "__main__":
    main()
