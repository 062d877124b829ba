#!/usr/bin/env python3
# Per target of a finished campaign: the estimate-frame localization error split into its
# vertical v (C_e's height less the true centroid's moved by the estimator's mean error over
# the localizing frames; + above) and horizontal h, beside the depth filter's own spread about
# C_e (sz, sh: 1σ of the 2000 points of targets/ID/points.ply, the set the rings were planned
# from) and v / sz. Works on runs whose mission.json predates `localized_sigma_m`.
# usage: localization_spread.py CAMPAIGN_DIR
import glob, json, math, os, struct, sys


def flown_targets(campaign_dir):
    """Yields (run folder, target of mission.json, true centroid, estimator error at
    localization, the filter's points) for every target matched to a true rock whose
    points.ply was written."""
    for mj in sorted(glob.glob(campaign_dir + '/runs/*/seed-*/mission.json')):
        d = os.path.dirname(mj)
        m = json.load(open(mj))
        rocks = {r['id']: r for r in json.load(open(d + '/world_gt/world.json'))['rocks']}
        for t in m['targets']:
            e = t.get('estimator_error_at_localization_m')
            p = f"{d}/targets/{t['id']}/points.ply"
            if t.get('gt_rock_id') is None or e is None or not os.path.exists(p):
                continue
            b = open(p, 'rb').read()
            i = b.index(b'end_header\n') + 11
            pts = [struct.unpack_from('<3f', b, i + 12 * k) for k in range((len(b) - i) // 12)]
            yield d, t, rocks[t['gt_rock_id']]['centroid'], e, pts


if __name__ == '__main__':
    for d, t, c, e, pts in flown_targets(sys.argv[1]):
        n = len(pts)
        mean = [sum(q[a] for q in pts) / n for a in range(3)]
        var = [sum((q[a] - mean[a]) ** 2 for q in pts) / n for a in range(3)]
        sz, sh = math.sqrt(var[2]), math.sqrt((var[0] + var[1]) / 2)
        L = t['localized_center']
        v = L[2] - c[2] - e[2]
        h = math.hypot(L[0] - c[0] - e[0], L[1] - c[1] - e[1])
        print('%-28s %2d v %+.2f sz %.2f z %+.1f | h %.2f sh %.2f' % (
            d.split('runs/')[1], t['id'], v, sz, v / sz, h, sh))
