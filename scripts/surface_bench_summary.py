#!/usr/bin/env python3
"""Per-keyframe timing summary of `omnisculpt surface` from OUT/stats/keyframes.csv.

Prints, over the incremental keyframes (the batch row excluded): ms per keyframe median / p95 / max
for the whole keyframe and for steps 1-5 alone (without step 6), the mean ms of each step, max |E|,
and the flatness ratio = mean time over the last fifth / over the first fifth, where keyframes of
the loop-closing zone are left out: those whose centre (OUT/poses.tum, one pose per keyframe) is
within --loop-radius metres of a keyframe at least --loop-gap keyframes older.

usage: surface_bench_summary.py OUT [--loop-radius 77] [--loop-gap 60]
"""
import argparse
import csv
import math
import os
import statistics


def quantile(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(q * len(v)))] if v else 0.0


def timing_summary(out, loop_radius=77.0, loop_gap=60):
    """The per-keyframe times of OUT/stats/keyframes.csv: a dict with the rows, the incremental
    rows, the loop-closing zone's count, ms per keyframe (all steps and steps 1-5) median / p95 /
    max and their flatness ratios."""
    rows = list(csv.DictReader(open(os.path.join(out, "stats", "keyframes.csv"))))
    centres = {}
    tum = os.path.join(out, "poses.tum")
    if os.path.exists(tum):
        for i, line in enumerate(l for l in open(tum) if l.strip() and not l.startswith("#")):
            f = line.split()
            centres[i] = tuple(float(x) for x in f[1:4])  # the rig origin: close to the centre
    inc = [r for r in rows if r["batch"] == "0"]
    f = lambda r, k: float(r.get(k, 0) or 0)
    # A row is a step of one or more keyframes (the keyframes column): its time per keyframe.
    per = lambda r: max(1.0, float(r.get("keyframes", 1) or 1))
    total = [f(r, "ms_total") / per(r) for r in inc]
    steps15 = [(f(r, "ms_total") - f(r, "ms_genus") - f(r, "ms_smooth")) / per(r) for r in inc]

    def in_loop_zone(r):
        k = int(r["keyframe"])
        if k not in centres:
            return False
        c = centres[k]
        return any(math.dist(c, centres[j]) < loop_radius for j in range(0, k - loop_gap)
                   if j in centres)

    kept = [(t, s) for r, t, s in zip(inc, total, steps15) if not in_loop_zone(r)]
    fifth = max(1, len(kept) // 5)
    flat = lambda i: (statistics.mean(x[i] for x in kept[-fifth:]) /
                      max(1e-9, statistics.mean(x[i] for x in kept[:fifth]))) if kept else 0.0
    return {"rows": rows, "incremental": inc, "loop_zone": len(inc) - len(kept),
            "total_median": quantile(total, .5), "total_p95": quantile(total, .95),
            "total_max": max(total, default=0), "total_flatness": flat(0),
            "steps15_median": quantile(steps15, .5), "steps15_p95": quantile(steps15, .95),
            "steps15_max": max(steps15, default=0), "steps15_flatness": flat(1)}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--loop-radius", type=float, default=77.0,
                    help="metres (default r + l of the paper with s = 1.9 m: 15 s + 15 s sqrt(3))")
    ap.add_argument("--loop-gap", type=int, default=60)
    a = ap.parse_args()
    t = timing_summary(a.out, a.loop_radius, a.loop_gap)
    rows, inc = t["rows"], t["incremental"]
    f = lambda r, k: float(r.get(k, 0) or 0)
    print(f"{a.out}: {len(rows)} rows, {len(inc)} incremental keyframes, "
          f"{t['loop_zone']} in the loop-closing zone")
    print(f"  ms per keyframe (all steps): median {t['total_median']:.1f} p95 "
          f"{t['total_p95']:.1f} max {t['total_max']:.1f}; flatness {t['total_flatness']:.2f}")
    print(f"  ms per keyframe (steps 1-5): median {t['steps15_median']:.1f} p95 "
          f"{t['steps15_p95']:.1f} max {t['steps15_max']:.1f}; flatness {t['steps15_flatness']:.2f}")
    print(f"  max |E| {max((int(r['cells_e']) for r in inc), default=0)}; cells in T at the end "
          f"{rows[-1]['cells_t'] if rows else 0}")
    keys = ["ms_steiner", "ms_enclose", "ms_shrink", "ms_insert", "ms_rays", "ms_rays_select",
            "ms_rays_old", "ms_grow", "ms_genus", "ms_smooth"]
    print("  mean ms: " + ", ".join(f"{k[3:]} {statistics.mean(f(r, k) for r in inc):.1f}"
                                     for k in keys if inc and k in inc[0]))
    added = sum(int(r["points_added"]) for r in rows)
    rejected = sum(int(r["points_rejected"]) for r in rows)
    print(f"  points added {added}, rejected {rejected} "
          f"({100.0 * rejected / max(1, added + rejected):.2f}%)")
    filters = ["points_invalid", "points_filtered_ground", "points_filtered_length",
               "points_filtered_aperture"]
    if rows and all(k in rows[0] for k in filters):
        print("  points filtered (paper 5.1): " +
              ", ".join(f"{k.split('_')[-1]} {sum(int(r[k]) for r in rows)}" for k in filters))
    if inc and "enclose_rounds" in inc[0]:
        print(f"  mean per keyframe: widening rounds {statistics.mean(f(r, 'enclose_rounds') for r in inc):.2f}, "
              f"cells added to E {statistics.mean(f(r, 'cells_e_added') for r in inc):.0f}, "
              f"active cells {statistics.mean(f(r, 'cells_active') for r in inc):.0f}, "
              f"smoothing candidates {statistics.mean(f(r, 'smoothing_candidates') for r in inc):.0f}"
              + (f", free cells grown around changes {statistics.mean(f(r, 'cells_grow_extra') for r in inc):.0f}"
                 if "cells_grow_extra" in inc[0] else ""))
    if inc and "old_ray_queries" in inc[0]:
        # Step 4's old rays (paper 4.4): candidates, their border queries and what a query costs.
        mean = lambda k: statistics.mean(f(r, k) for r in inc)
        per_query = lambda k: sum(f(r, k) for r in inc) / max(1.0, sum(f(r, "old_ray_queries") for r in inc))
        print(f"  old rays per keyframe: candidates {mean('rays_old_candidates'):.0f}, crossing N "
              f"{mean('rays_old'):.0f}, cells visited {mean('old_walk_cells'):.0f}; border facets "
              f"{mean('old_ray_facets'):.0f} (left out uncrossed {mean('old_ray_facets_uncrossed'):.0f}); "
              f"per query: voxels {per_query('old_ray_query_voxels'):.1f}, facets tested "
              f"{per_query('old_ray_facet_tests'):.1f}, past the plane filter "
              f"{per_query('old_ray_plane_passes'):.1f}")


if __name__ == "__main__":
    main()
