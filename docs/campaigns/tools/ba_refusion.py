#!/usr/bin/env python3
"""How bundle adjustment moved each target's map, and what the re-fusion made of it.

usage: ba_refusion.py CAMPAIGN_DIR [CAMPAIGN_DIR ...]

For every target folder of each campaign (keyframes_{odometry,ba}.txt, as a mission writes
them) prints, per campaign:
- the map's pull: |mean(BA position − odometry position)| over the keyframes, metres (median,
  p90, max);
- the keyframe-to-keyframe change of BA's correction `ba · odometry⁻¹`, the quantity
  `refine.between_max_correction_change_*` bounds (median over targets of each target's
  median, in mm and degrees; and how many stretches exceed 5 mm / 0.25° and 2 cm / 1°);
- how many targets lost more than 0.02 of F@2cm in BA (`fscore_2cm_before_ba` →
  `fscore_2cm` of mission.json), listed.
"""
import glob
import json
import math
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kf_jumps import angle_deg, read_tum, relative  # noqa: E402


def correction(odometry, refined):
    """refined · odometry⁻¹ as (translation, rotation matrix)."""
    r_o = odometry[2]
    r = [[sum(refined[2][i][k] * r_o[j][k] for k in range(3)) for j in range(3)] for i in range(3)]
    t = [refined[1][i] - sum(r[i][k] * odometry[1][k] for k in range(3)) for i in range(3)]
    return (0.0, t, r)


def percentile(values, q):
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))]


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for campaign in sys.argv[1:]:
        pulls, changes_mm, changes_deg, losses = [], [], [], []
        over_old = over_new = stretches = 0
        for mission in sorted(glob.glob(f"{campaign}/runs/*/seed-*/mission.json")):
            run = os.path.dirname(mission)
            for row in json.load(open(mission))["targets"]:
                target = f"{run}/targets/{row['id']}"
                if not os.path.exists(f"{target}/keyframes_ba.txt"):
                    continue
                odometry = read_tum(f"{target}/keyframes_odometry.txt")
                refined = read_tum(f"{target}/keyframes_ba.txt")
                n = len(odometry)
                mean = [sum(b[1][i] - o[1][i] for o, b in zip(odometry, refined)) / n for i in range(3)]
                pulls.append(math.hypot(*mean))
                c = [correction(o, b) for o, b in zip(odometry, refined)]
                mm, deg = [], []
                for a, b in zip(c, c[1:]):
                    step_m, r = relative(a, b)
                    mm.append(1e3 * math.hypot(*step_m))
                    deg.append(angle_deg(r, [[float(i == j) for j in range(3)] for i in range(3)]))
                    stretches += 1
                    over_old += mm[-1] > 5 or deg[-1] > 0.25
                    over_new += mm[-1] > 20 or deg[-1] > 1
                if mm:
                    changes_mm.append(statistics.median(mm))
                    changes_deg.append(statistics.median(deg))
                before, after = row.get("fscore_2cm_before_ba"), row.get("fscore_2cm")
                if before is not None and after is not None and after < before - 0.02:
                    losses.append(f"{os.path.relpath(run, campaign)} target {row['id']}: "
                                  f"F@2cm {before:.3f} -> {after:.3f}")
        if not pulls:
            print(f"{campaign}: no targets with keyframes")
            continue
        print(f"{campaign}: {len(pulls)} targets")
        print(f"  pull (m): median {statistics.median(pulls):.2f}, p90 {percentile(pulls, 0.9):.2f}, "
              f"max {max(pulls):.2f}")
        print(f"  correction change per keyframe: median {statistics.median(changes_mm):.2f} mm, "
              f"{statistics.median(changes_deg):.3f}°; stretches over 5 mm / 0.25°: {over_old} "
              f"of {stretches}, over 2 cm / 1°: {over_new}")
        print(f"  targets losing > 0.02 of F@2cm in BA: {len(losses)}")
        for line in losses:
            print(f"    {line}")


if __name__ == "__main__":
    main()
