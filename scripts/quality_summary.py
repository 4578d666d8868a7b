#!/usr/bin/env python3
"""The table of scripts/quality.sh: one row per run (build, drive, start) read from each run's
report/eval.json, the means per build, and with two builds the mean of the paired differences
B - A with their range. Usage: quality_summary.py OUT (the folder holding runs.tsv)."""

import csv
import json
import os
import statistics
import sys

# The labels of a synth drive's ground truth that are objects in front of the walls and the
# ground (docs/figures.md F81: what the surface loses behind the truth).
OBJECTS = ("trim", "pole", "trunk", "crown", "car")


def objects(d, key):
    """Over the pixels whose true hit is on an object: the recall at 0.5 m ("recall") or the
    share of their both-hit pixels behind the truth ("behind"); KeyError without labels."""
    rows = [p for p in d["pixel"]["labels"] if p["label"] in OBJECTS]
    if key == "recall":
        return sum(p["precision_recall"][1]["within"] for p in rows) / sum(
            p["gt_hits"] for p in rows)
    return sum(p["tail_behind_count"] for p in rows) / sum(p["both_hits"] for p in rows)


# (column, unit scale, digits, how to read it from eval.json)
COLUMNS = [
    ("F@0.2", 1, 3, lambda d: d["pixel"]["precision_recall"][0]["f_score"]),
    ("F@0.5", 1, 3, lambda d: d["pixel"]["precision_recall"][1]["f_score"]),
    ("P@0.5", 1, 3, lambda d: d["pixel"]["precision_recall"][1]["precision"]),
    ("R@0.5", 1, 3, lambda d: d["pixel"]["precision_recall"][1]["recall"]),
    ("tail %", 100, 1, lambda d: d["pixel"]["tail"]),
    ("in front %", 100, 1, lambda d: d["pixel"]["tail_front"]),
    ("q90 cm", 100, 0, lambda d: d["ray_errors"]["quantiles_m"]["q90"]),
    ("> 6 m %", 100, 2, lambda d: d["ray_errors"]["share_above_6m"]),
    ("closed q90 cm", 100, 0,
     lambda d: d["closed_surface"]["ray_errors"]["quantiles_m"]["q90"]),
    ("closed > 6 m %", 100, 1, lambda d: d["closed_surface"]["ray_errors"]["share_above_6m"]),
    ("ATE cm", 100, 2, lambda d: d["poses"]["ate_translation_m"]["rmse"]),
    # Drives made before synth labelled its triangles: "—".
    ("objects R@0.5", 1, 3, lambda d: objects(d, "recall")),
    ("objects behind %", 100, 1, lambda d: objects(d, "behind")),
]


def read(folder):
    path = os.path.join(folder, "report", "eval.json")
    if not os.path.exists(path):
        return None
    d = json.load(open(path))
    values = []
    for _, scale, _, get in COLUMNS:
        try:
            values.append(scale * float(get(d)))
        except (KeyError, IndexError, TypeError, ValueError, ZeroDivisionError):
            values.append(float("nan"))
    return values


def fmt(values):
    return " | ".join(
        "—" if v != v else f"{v:.{digits}f}" for v, (_, _, digits, _) in zip(values, COLUMNS))


def mean(rows):
    return [statistics.fmean(col) if all(v == v for v in col) else float("nan")
            for col in zip(*rows)]


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: quality_summary.py OUT")
    out = sys.argv[1]
    runs = list(csv.DictReader(open(os.path.join(out, "runs.tsv")), delimiter="\t"))
    if os.path.exists(os.path.join(out, "machine.txt")):
        for line in open(os.path.join(out, "machine.txt")):
            print(line.rstrip())
        print()
    header = "| build | drive | start | " + " | ".join(c[0] for c in COLUMNS) + " |"
    print(header)
    print("|" + "---|" * (3 + len(COLUMNS)))
    by_key = {}
    for run in runs:
        values = read(run["folder"]) if run["exit"] == "0" else None
        if values is None:
            print(f"| {run['label']} | {run['drive']} | {run['start']} | failed (exit {run['exit']}) |")
            continue
        by_key[(run["label"], run["drive"], run["start"])] = values
        print(f"| {run['label']} | {run['drive']} | {run['start']} | {fmt(values)} |")
    labels = sorted({k[0] for k in by_key})
    print()
    print("| build | runs | " + " | ".join(c[0] for c in COLUMNS) + " |")
    print("|" + "---|" * (2 + len(COLUMNS)))
    for label in labels:
        rows = [v for k, v in by_key.items() if k[0] == label]
        print(f"| {label} mean | {len(rows)} | {fmt(mean(rows))} |")
    if labels == ["A", "B"]:
        pairs = [(by_key[("A",) + k[1:]], v) for k, v in by_key.items()
                 if k[0] == "B" and ("A",) + k[1:] in by_key]
        if pairs:
            diffs = [[b - a for a, b in zip(pa, pb)] for pa, pb in pairs]
            print(f"| B − A mean | {len(pairs)} | {fmt(mean(diffs))} |")
            low = [min(col) for col in zip(*diffs)]
            high = [max(col) for col in zip(*diffs)]
            print(f"| B − A lowest | {len(pairs)} | {fmt(low)} |")
            print(f"| B − A highest | {len(pairs)} | {fmt(high)} |")


if __name__ == "__main__":
    main()
