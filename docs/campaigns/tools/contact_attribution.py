#!/usr/bin/env python3
"""Which part of a target's α_min error is the contact outline's, and which the centre of mass's.

For each mission folder and true rock id, recomputes α_min = min over azimuths of
atan(support distance of the contact polygon beyond the centre of mass / its height) from
`fragility.json` (estimate) and `world_gt/world.json` (truth), then swaps the parts. The true
polygon is moved under the scan's centre of mass, since the map frame differs from the truth's
by the navigation error. The formula reproduces the reported α to a few tenths of a degree.
When "true polygon, scan's centre of mass" gives the truth, the outline carries the error.

Usage:
    python3 docs/campaigns/tools/contact_attribution.py ROCK_ID RUN_DIR [RUN_DIR ...]
    python3 docs/campaigns/tools/contact_attribution.py 2 camp/runs/library-a/seed-6*
"""
import json
import math
import sys


def alpha_min_deg(polygon, com_xy, height_m):
    """(α_min in degrees, its azimuth in whole degrees from east, counter-clockwise)."""
    best = (math.inf, 0)
    for k in range(360):
        u = (math.cos(math.radians(k)), math.sin(math.radians(k)))
        reach = max((p[0] - com_xy[0]) * u[0] + (p[1] - com_xy[1]) * u[1] for p in polygon)
        best = min(best, (math.degrees(math.atan2(reach, height_m)), k))
    return best


def main():
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    rock_id = int(sys.argv[1])
    print("run | reported | truth | formula est | formula truth | est outline, true height "
          "| true outline under the scan's centre")
    for run in sys.argv[2:]:
        mission = json.load(open(f"{run}/mission.json"))
        world = json.load(open(f"{run}/world_gt/world.json"))
        target = next((t for t in mission["targets"] if t.get("gt_rock_id") == rock_id), None)
        rock = next(r for r in world["rocks"] if r["id"] == rock_id)
        if target is None or target.get("alpha_min_deg") is None:
            print(f"{run} | not analysed")
            continue
        est = json.load(open(f"{run}/targets/{target['id']}/fragility.json"))
        com, centroid = est["center_of_mass"], rock["centroid"]
        true_height = centroid[2] - rock["contact"]["height_m"]
        est_height = est["com_height_above_contact_m"]
        offset = (com[0] - centroid[0], com[1] - centroid[1])
        true_moved = [(p[0] + offset[0], p[1] + offset[1]) for p in rock["contact"]["polygon_xy_m"]]
        a_est = alpha_min_deg(est["contact_polygon"], com, est_height)
        a_true = alpha_min_deg(rock["contact"]["polygon_xy_m"], centroid, true_height)
        print(f"{run} | {target['alpha_min_deg']:.2f} | {target['alpha_min_gt_deg']:.2f} | "
              f"{a_est[0]:.2f} at {a_est[1]}° | {a_true[0]:.2f} at {a_true[1]}° | "
              f"{alpha_min_deg(est['contact_polygon'], com, true_height)[0]:.2f} | "
              f"{alpha_min_deg(true_moved, com, est_height)[0]:.2f}")


if __name__ == "__main__":
    main()
