#!/usr/bin/env python3
"""Session 49 (#17): candidate heights of a target's centre, from the per-keyframe depth inside
its boxes, against the truth in the frame the vehicle flew in.

Build a binary with `git apply docs/campaigns/tools/session49_height_diag.patch` (it prints
LOCDIAG at the start of each target's mapping and VIEWDIAG per localization keyframe box on
stderr), fly `scarp simulate --world W --seed S --out d-W-S 2> d-W-S.err`, then run this in the
folder holding the d-*.err files and their run folders:

    python3 height_estimators.py

Per target it prints the error (m, + = above the centroid moved by the estimator's mean error
over the localization) of: now (the filter's C_e), tri (the point nearest all box-centre rays),
ray (each box-centre ray's height at the located horizontal centre), mid99 (halfway from the
ground at the foot to the object's 99th-percentile height), mido / mid95o (halfway from the
object's 5th to its 99th / 95th percentile height), sph (a round body's centre from its top and
lowest visible point at the view's elevation), surf (the surface at the box centre) and med50
(the object points' median). Each is the median over the target's keyframe views.

It then prints the point nearest the box-centre rays (what `localization::triangulation`
computes) three ways: in the frame flown, and with each ray moved to its keyframe's true pose
(the keyframe found in the run's `trajectory.txt` by its camera position, its estimator error
read against `groundtruth.txt`), vertically and horizontally, and its 3D count within 0.5 m.
"""
import glob
import json
import math

import numpy as np


def med(values):
    values = [x for x in values if x == x]
    return float(np.median(values)) if values else float("nan")


def rays_nearest_point(rays):
    """The point nearest all rays (E, unit d), with a few Huber-like reweightings."""
    weights = np.ones(len(rays))
    point = np.full(3, np.nan)
    for _ in range(5):
        a, b = np.zeros((3, 3)), np.zeros(3)
        for (e, d), w in zip(rays, weights):
            p = np.eye(3) - np.outer(d, d)
            a += w * p
            b += w * p @ e
        point = np.linalg.solve(a, b)
        res = np.array([np.linalg.norm((np.eye(3) - np.outer(d, d)) @ (point - e)) for e, d in rays])
        scale = max(1.4826 * np.median(res), 0.05)
        weights = np.where(res < 2 * scale, 1.0, 2 * scale / res)
    return point


def load_tum_positions(path):
    rows = [line.split() for line in open(path) if not line.startswith("#")]
    return np.array([[float(x) for x in r[1:4]] for r in rows])


KEYS = ["now", "tri", "ray", "mid99", "mido", "mid95o", "sph", "surf", "med50"]
rows = []
rays_rows = []
for err in sorted(glob.glob("d-*.err")):
    run = err[:-4]
    try:
        mission = json.load(open(run + "/mission.json"))
    except (OSError, ValueError):
        continue
    rocks = {r["id"]: r for r in json.load(open(run + "/world_gt/world.json"))["rocks"]}
    estimated = load_tum_positions(run + "/trajectory.txt")
    estimator_error = estimated - load_tum_positions(run + "/groundtruth.txt")
    targets = {t["id"]: t for t in mission["targets"]}
    views = {}
    for line in open(err):
        if "VIEWDIAG" in line:
            v = json.loads(line.split("VIEWDIAG ", 1)[1])
            views.setdefault(v["id"], []).append(v)
            continue
        if "LOCDIAG" not in line:
            continue
        j = json.loads(line.split("LOCDIAG ", 1)[1])
        t = targets.get(j["id"])
        if not t or t.get("gt_role") != "target" or t.get("estimator_error_at_localization_m") is None:
            continue
        truth = np.array(rocks[t["gt_rock_id"]]["centroid"]) + np.array(t["estimator_error_at_localization_m"])
        c = np.array(j["center"])
        est = {k: [] for k in KEYS if k not in ("now", "tri")}
        rays, true_rays = [], []
        for v in views.get(j["id"], []):
            e, s = np.array(v["eye"]), np.array(v["surface"])
            d = s - e
            horizontal = math.hypot(d[0], d[1])
            elevation = math.degrees(math.atan2(-d[2], horizontal))
            if elevation > 75:
                continue
            q = v["oq"]  # object heights at the 5, 25, 50, 75, 90, 95, 99th percentiles
            forward = d[:2] / horizontal
            est["ray"].append(e[2] + (forward @ (c[:2] - e[:2])) / horizontal * d[2])
            est["mid99"].append(0.5 * (v["ground"] + q[6]))
            est["mido"].append(0.5 * (q[0] + q[6]))
            est["mid95o"].append(0.5 * (q[0] + q[5]))
            est["sph"].append(q[6] - (q[6] - q[0]) / (1 + math.cos(math.radians(elevation))))
            est["surf"].append(s[2])
            est["med50"].append(q[2])
            rays.append((e, d / np.linalg.norm(d)))
            frame_error = estimator_error[np.argmin(np.linalg.norm(estimated - e, axis=1))]
            true_rays.append((e - frame_error, d / np.linalg.norm(d)))
        row = {"run": run, "rock": t["gt_rock_id"], "h": np.linalg.norm(c[:2] - truth[:2]), "now": c[2] - truth[2]}
        row["tri"] = (rays_nearest_point(rays)[2] if len(rays) >= 3 else float("nan")) - truth[2]
        for k, values in est.items():
            row[k] = med(values) - truth[2]
        rows.append(row)
        if len(rays) >= 3:
            centroid = np.array(rocks[t["gt_rock_id"]]["centroid"])
            flown = rays_nearest_point(rays) - truth
            true = rays_nearest_point(true_rays) - centroid
            rays_rows.append((flown[2], np.linalg.norm(flown[:2]), true[2], np.linalg.norm(true[:2]), np.linalg.norm(flown)))

print("%-16s rk    h " % "run" + " ".join("%6s" % k for k in KEYS))
for r in rows:
    print("%-16s %d %5.2f " % (r["run"], r["rock"], r["h"]) + " ".join("%+6.2f" % r[k] for k in KEYS))
h = np.array([r["h"] for r in rows])
for k in KEYS:
    z = np.array([r[k] for r in rows])
    ok = ~np.isnan(z)
    print(
        "%6s: |z| median %.2f, 90th percentile %.2f; within 0.5 m in 3D (with the located horizontal) %d / %d"
        % (k, np.median(abs(z[ok])), np.percentile(abs(z[ok]), 90), (np.hypot(h[ok], z[ok]) <= 0.5).sum(), len(rows))
    )

a = np.array(rays_rows)
print("the rays' nearest point (median, 90th percentile, m):")
for name, k in [("vertical, frame flown", 0), ("horizontal, frame flown", 1), ("vertical, true poses", 2), ("horizontal, true poses", 3)]:
    print("  %-24s %.2f %.2f" % (name, np.median(abs(a[:, k])), np.percentile(abs(a[:, k]), 90)))
print("  within 0.5 m in 3D, frame flown: %d / %d" % ((a[:, 4] <= 0.5).sum(), len(a)))
