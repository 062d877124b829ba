#!/usr/bin/env python3
"""C_e's estimate-frame error split into horizontal and vertical, per campaign folder, and,
with --pair, the targets two campaigns both flew compared by their horizontal error.

Usage:
    python3 docs/campaigns/tools/localization_split.py CAMPAIGN_DIR...
    python3 docs/campaigns/tools/localization_split.py --pair BEFORE_DIR AFTER_DIR
"""
import glob
import json
import math
import statistics
import sys


def targets(root):
    """(run, true rock id) → (horizontal m, vertical m, 3D m) of every localized true target."""
    out = {}
    for mission_json in glob.glob(root + "/runs/*/*/mission.json"):
        run = "/".join(mission_json.split("/")[-3:-1])
        for t in json.load(open(mission_json))["targets"]:
            offset = t.get("localization_offset_estimate_frame_m")
            if t.get("gt_role") == "target" and offset:
                out[(run, t["gt_rock_id"])] = (
                    math.hypot(offset[0], offset[1]), offset[2],
                    t["localization_error_estimate_frame_m"])
    return out


def main():
    if len(sys.argv) == 4 and sys.argv[1] == "--pair":
        before, after = targets(sys.argv[2]), targets(sys.argv[3])
        both = [k for k in after if k in before]
        h0 = [before[k][0] for k in both]
        h1 = [after[k][0] for k in both]
        print(f"{len(both)} targets in both: horizontal median {statistics.median(h0):.2f} -> "
              f"{statistics.median(h1):.2f} m; better on {sum(b < a for a, b in zip(h0, h1))}")
        return
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    for root in sys.argv[1:]:
        rows = list(targets(root).values())
        h = sorted(r[0] for r in rows)
        print(f"{root}: {len(rows)} targets; within 0.5 m {sum(r[2] <= 0.5 for r in rows)}; "
              f"horizontal median {statistics.median(h):.2f}, worst {h[-1]:.2f} m, "
              f"over 0.5 m {sum(x > 0.5 for x in h)}; vertical median "
              f"{statistics.median(r[1] for r in rows):+.2f} m, over 0.5 m "
              f"{sum(abs(r[1]) > 0.5 for r in rows)}")


if __name__ == "__main__":
    main()
