"""Takes a localized centre (C_e) apart, from runs flown with the ray diagnostic.

Build the diagnostic binary with `git apply docs/campaigns/tools/session64_ray_diag.patch`,
fly with `SCARP_RAY_DIAG=RUN/rays.jsonl scarp simulate ... --out RUN/out`, then

    python3 docs/campaigns/tools/localization_rays.py RUN...

For each target it prints the arc its keyframe boxes were seen from (360° less the widest gap),
and the offset of the rays' meeting point from the truth in the estimate's frame (the true
centroid moved by the estimator's mean error, as `mission.json` has it), recomputed:
- `as flown`: the estimated origins and directions (it reproduces `mission.json`);
- `true poses`: each ray moved to its keyframe's true pose (box and shape error alone);
- `walk only`: estimated origins, true directions (the position walk alone);
- `attitude only`: true origins, estimated directions.
Needs numpy.
"""
import json
import os
import sys

import numpy as np


def meeting_point(origins, directions, rounds=5, min_scale_m=0.05):
    """The robust least-squares point nearest the rays, as `triangulation::nearest_point`."""
    weights = np.ones(len(origins))
    point = None
    for _ in range(rounds):
        normal, rhs = np.zeros((3, 3)), np.zeros(3)
        for o, d, w in zip(origins, directions, weights):
            across = np.eye(3) - np.outer(d, d)
            normal += w * across
            rhs += w * across @ o
        point = np.linalg.solve(normal, rhs)
        dist = np.array([np.linalg.norm((np.eye(3) - np.outer(d, d)) @ (point - o))
                         for o, d in zip(origins, directions)])
        delta = 2.0 * max(1.4826 * np.median(dist), min_scale_m)
        weights = np.where(dist <= delta, 1.0, delta / np.maximum(dist, 1e-12))
    return point


def view_arc_deg(origins, center):
    az = np.sort(np.degrees(np.arctan2(origins[:, 1] - center[1], origins[:, 0] - center[0])))
    gaps = np.diff(np.concatenate([az, [az[0] + 360.0]]))
    return 360.0 - gaps.max()


def targets(run):
    rows = [json.loads(line) for line in open(os.path.join(run, "rays.jsonl"))]
    mission = json.load(open(os.path.join(run, "out", "mission.json")))
    for target in mission["targets"]:
        offset = target.get("localization_offset_estimate_frame_m")
        if offset is None:
            continue
        rays = [r for r in rows if r["id"] == target["id"] and r["localizing"]]
        # Only the rays of the filter's last life: a restart starts the count at 1 again.
        restarts = [i for i, r in enumerate(rays) if r["n"] == 1]
        rays = rays[restarts[-1]:] if restarts else rays
        origins = np.array([r["o"] for r in rays])
        directions = np.array([r["d"] for r in rays])
        walk = np.array([r["b"] for r in rays])
        true_directions = np.array([r["dt"] for r in rays])
        mean_walk = np.array(target["estimator_error_at_localization_m"])
        reference = np.array(target["localized_center"]) - np.array(offset)
        true_centroid = reference - mean_walk
        flown = meeting_point(origins, directions)
        yield dict(
            run=os.path.basename(os.path.normpath(run)), id=target["id"],
            rock=target.get("gt_rock_id"), rays=len(rays),
            arc=view_arc_deg(origins, flown),
            flown=flown - reference,
            true=meeting_point(origins - walk, true_directions) - true_centroid,
            walk=meeting_point(origins, true_directions) - reference,
            attitude=meeting_point(origins - walk, directions) - true_centroid,
        )


def show(v):
    return "(" + ", ".join(f"{x:+.2f}" for x in v) + f") {np.linalg.norm(v):.2f}"


def main(runs):
    found = [t for run in runs if os.path.exists(os.path.join(run, "out", "mission.json"))
             for t in targets(run)]
    for t in found:
        print(f"{t['run']:14s} target {t['id']:2d} rock {t['rock']} rays {t['rays']:3d} "
              f"arc {t['arc']:4.0f}°  as flown {show(t['flown'])}  true poses {show(t['true'])}  "
              f"walk only {show(t['walk'])}  attitude only {show(t['attitude'])}")
    if found:
        errors = np.array([np.linalg.norm(t["flown"]) for t in found])
        arcs = np.array([t["arc"] for t in found])
        print(f"{len(found)} targets: median {np.median(errors):.2f} m, worst {errors.max():.2f} m, "
              f"over 0.5 m {int((errors > 0.5).sum())}; arc median {np.median(arcs):.0f}°, "
              f"least {arcs.min():.0f}°")


if __name__ == "__main__":
    main(sys.argv[1:])
