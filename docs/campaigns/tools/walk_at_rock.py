#!/usr/bin/env python3
# Per target: the estimate's error over the localization window [found_at, fine_localize → map],
# as seen at the rock: the estimate's position error plus its attitude error moved to the rock
# (the point the camera believes it sees at the rock's true place, less the rock), each less the
# reference the estimate-frame metric subtracts, and their correlation with C_e's vertical error.
# Needs numpy. usage: walk_at_rock.py CAMPAIGN_DIR [...]
import glob, json, os, re, sys
import numpy as np
def rot(qx, qy, qz, qw):
    return np.array([[1-2*(qy*qy+qz*qz), 2*(qx*qy-qz*qw), 2*(qx*qz+qy*qw)],
                     [2*(qx*qy+qz*qw), 1-2*(qx*qx+qz*qz), 2*(qy*qz-qx*qw)],
                     [2*(qx*qz-qy*qw), 2*(qy*qz+qx*qw), 1-2*(qx*qx+qy*qy)]])
rows = []
for d0 in sys.argv[1:]:
  for mj in sorted(glob.glob(d0 + '/runs/*/seed-*/mission.json')):
    d = os.path.dirname(mj)
    m = json.load(open(mj))
    est, gt = np.loadtxt(d + '/trajectory.txt'), np.loadtxt(d + '/groundtruth.txt')
    log = open(d + '/run.log').read()
    rocks = {r['id']: r for r in json.load(open(d + '/world_gt/world.json'))['rocks']}
    for t in m['targets']:
        if t.get('gt_rock_id') is None or t.get('localization_offset_estimate_frame_m') is None:
            continue
        mm = re.search(r't = ([0-9.]+) s: fine_localize → map \(target %d\)' % t['id'], log)
        if not mm: continue
        t0, t1 = t['found_at_s'], float(mm.group(1))
        c = np.array(rocks[t['gt_rock_id']]['centroid'])
        sel = (gt[:, 0] >= t0) & (gt[:, 0] <= t1)
        pos = est[sel, 1:4] - gt[sel, 1:4]
        # Where the estimate puts the rock: world_from_cam_est * cam_from_world_gt * c.
        seen = []
        for e, g in zip(est[sel], gt[sel]):
            Re, Rg = rot(*e[4:8]), rot(*g[4:8])
            pc = Rg.T @ (c - g[1:4])
            seen.append(Re @ pc + e[1:4] - c)
        seen = np.array(seen)
        off = np.array(t['localization_offset_estimate_frame_m'])
        ref = np.array(t['estimator_error_at_localization_m'])
        # v = C_e - c - ref; the C_e error against the rock as seen: C_e - c - seen.mean
        v = off[2]
        rows.append((v, seen[:, 2].mean() - ref[2], (seen[:, 2].min() + seen[:, 2].max()) / 2 - ref[2],
                     seen[-len(seen)//4:, 2].mean() - ref[2], pos[:, 2].mean() - ref[2]))
        print('%-30s %2d v %+.2f | seen-z mean-ref %+.2f  mid-ref %+.2f  last25-ref %+.2f  pos-ref %+.2f  range seen %.2f pos %.2f  n %d' % (
            d.split('runs/')[1], t['id'], v, *rows[-1][1:], np.ptp(seen[:, 2]), np.ptp(pos[:, 2]), sel.sum()))
r = np.array(rows)
for i, name in enumerate(['seen mean', 'seen mid', 'seen last25', 'pos mean'], 1):
    cc = np.corrcoef(r[:, 0], r[:, i])[0, 1]
    res = r[:, 0] - r[:, i]
    print('%-12s corr %.2f  sd(v) %.2f -> sd(v - it) %.2f' % (name, cc, r[:, 0].std(), res.std()))
