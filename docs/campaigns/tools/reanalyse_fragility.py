#!/usr/bin/env python3
"""Re-analyse every true target's mission mesh (F@2cm ≥ 0.85) of campaign folders with a scarp
binary, as the mission analyses it (`scarp fragility --scan --json`), and tabulate α against the
truth: analysed, refused, |error| ≤ 2°, overestimates over 3°, truth inside, median width, mean
|error| and median error, and each interval source's median half-widths.
With --pair, compare two such result files mesh by mesh instead.

Usage:
    JOBS=2 python3 docs/campaigns/tools/reanalyse_fragility.py BINARY OUT.json CAMPAIGN_DIR...
    python3 docs/campaigns/tools/reanalyse_fragility.py --pair BEFORE.json AFTER.json

Session 46 chose `[fragility.scan] contact_near_m` with it.
"""
import glob
import json
import os
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor


def meshes(roots):
    for root in roots:
        for mission_json in sorted(glob.glob(root + "/runs/*/*/mission.json")):
            run = os.path.dirname(mission_json)
            for t in json.load(open(mission_json))["targets"]:
                mesh = f"{run}/targets/{t['id']}/mesh.ply"
                if (t.get("gt_role") == "target" and os.path.exists(mesh)
                        and (t.get("fscore_2cm") or 0) >= 0.85):
                    yield run, t["gt_rock_id"], mesh, t["alpha_min_gt_deg"]


def analyse(binary, job):
    run, rock, mesh, truth = job
    out = subprocess.run([binary, "fragility", "--scan", "--json", mesh],
                         capture_output=True, text=True)
    row = dict(run=run, rock=rock, gt=truth)
    if out.returncode:
        row["error"] = out.stderr.strip().splitlines()[-1][-160:]
    else:
        f = json.loads(out.stdout)
        row.update(alpha=f["alpha_min_deg"], low=f["alpha_min_low_deg"],
                   high=f["alpha_min_high_deg"], sources=f["alpha_interval"]["sources"])
    return row


def describe(r):
    if "alpha" in r:
        return f"{r['alpha']:.2f} [{r['low']:.2f}, {r['high']:.2f}]"
    return "refused: " + r["error"][-80:]


def pair(before_path, after_path):
    before = {(r["run"], r["rock"]): r for r in json.load(open(before_path))}
    for r in json.load(open(after_path)):
        b = before.get((r["run"], r["rock"]))
        if b is None or ("alpha" not in b and "alpha" not in r):
            continue
        moved = ("alpha" in b) != ("alpha" in r) or (
            "alpha" in r and (abs(b["alpha"] - r["alpha"]) > 0.05 or abs(b["low"] - r["low"]) > 0.05))
        if moved:
            print(f"{r['run'].split('/runs/')[-1]} rock {r['rock']} truth {r['gt']:.2f}: "
                  f"{describe(b)} -> {describe(r)}")


def main():
    if len(sys.argv) == 4 and sys.argv[1] == "--pair":
        return pair(sys.argv[2], sys.argv[3])
    if len(sys.argv) < 4:
        raise SystemExit(__doc__)
    binary, out_path = sys.argv[1], sys.argv[2]
    jobs = list(meshes(sys.argv[3:]))
    with ThreadPoolExecutor(int(os.environ.get("JOBS", "2"))) as pool:
        rows = list(pool.map(lambda j: analyse(binary, j), jobs))
    json.dump(rows, open(out_path, "w"), indent=1)
    done = [r for r in rows if "alpha" in r]
    errors = [r["alpha"] - r["gt"] for r in done]
    within = sum(abs(e) <= 2 for e in errors)
    inside = sum(r["low"] <= r["gt"] <= r["high"] for r in done)
    width = statistics.median(r["high"] - r["low"] for r in done) if done else float("nan")
    print(f"{len(rows)} meshes, {len(done)} analysed, {len(rows) - len(done)} refused")
    print(f"|error| <= 2°: {within}/{len(done)} analysed; over +3°: {sum(e > 3 for e in errors)}; "
          f"truth inside: {inside}/{len(done)}; median width {width:.2f}°")
    if done:
        print(f"mean |error| {statistics.mean(abs(e) for e in errors):.2f}°, median error "
              f"{statistics.median(errors):+.2f}°")
        names = sorted({s["name"] for r in done for s in r["sources"]})
        print("interval sources, median below / above (°): " + ", ".join(
            f"{n} {statistics.median(s['below_deg'] for r in done for s in r['sources'] if s['name'] == n):.2f}"
            f" / {statistics.median(s['above_deg'] for r in done for s in r['sources'] if s['name'] == n):.2f}"
            for n in names))
    for r in sorted(done, key=lambda r: -abs(r["alpha"] - r["gt"]))[:6]:
        print(f"  {r['run'].split('/runs/')[-1]} rock {r['rock']}: {describe(r)}, truth {r['gt']:.2f}")


if __name__ == "__main__":
    main()
