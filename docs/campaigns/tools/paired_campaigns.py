#!/usr/bin/env python3
# Target by target, two campaign directories flown on the same worlds and seeds (for example two
# configurations): alpha error, interval width and whether it holds the truth, F@1/2cm and
# estimate-frame localization; per run wall, map and BA times; paired totals (with frames
# dropped, searches after drops and localizations within 0.5 m in the estimate frame).
# usage: paired_campaigns.py CAMP_A CAMP_B
import json, sys, glob, os, statistics as st
a, b = sys.argv[1], sys.argv[2]
rows = []
def num(x, fmt):
    return '-' if x is None else fmt % x
def interval(t):
    """(width, truth inside) of a target's alpha_min interval, or None without one."""
    lo, hi, g = t.get('alpha_min_low_deg'), t.get('alpha_min_high_deg'), t.get('alpha_min_gt_deg')
    if lo is None or hi is None or g is None:
        return None
    return hi - lo, lo <= g <= hi
for run in sorted(glob.glob(a + '/runs/*/seed-*/mission.json')):
    rel = os.path.relpath(run, a)
    other = os.path.join(b, rel)
    if not os.path.exists(other):
        continue
    ma, mb = json.load(open(run)), json.load(open(other))
    print(rel.split('/mission.json')[0], 'wall %.0f/%.0f map %.0f/%.0f ba %.0f/%.0f coll %s/%s clr %s/%s' % (
        ma['wall_time_s'], mb['wall_time_s'], ma['timings']['map_s'], mb['timings']['map_s'],
        ma['timings']['ba_mesh_s'], mb['timings']['ba_mesh_s'], ma['collisions'], mb['collisions'],
        num(ma['min_clearance_m'], '%.2f'), num(mb['min_clearance_m'], '%.2f')))
    ta = {t['gt_rock_id']: t for t in ma['targets'] if t.get('gt_role') == 'target'}
    tb = {t['gt_rock_id']: t for t in mb['targets'] if t.get('gt_role') == 'target'}
    for rid in sorted(set(ta) | set(tb)):
        x, y = ta.get(rid, {}), tb.get(rid, {})
        rows.append((x, y))
        def f(t):
            e = t.get('alpha_error_deg')
            iv = interval(t) if e is not None else None
            return '%-10s a %6s w %5s %3s F1 %5s F2 %5s loc %4s' % (
                t.get('status', 'absent'), num(e, '%+.2f'),
                num(iv and iv[0], '%.2f'), '' if iv is None else ('in' if iv[1] else 'OUT'),
                num(t.get('fscore_1cm'), '%.3f'), num(t.get('fscore_2cm'), '%.3f'),
                num(t.get('localization_error_estimate_frame_m'), '%.2f'))
        print('  rock', rid, '|', f(x), '|', f(y))
def tot(i):
    ts = [r[i] for r in rows]
    al = [t for t in ts if t.get('alpha_error_deg') is not None]
    ok = sum(abs(t['alpha_error_deg']) <= 2 for t in al)
    ivs = [iv for iv in map(interval, al) if iv is not None]
    inside = sum(held for _, held in ivs)
    w = [width for width, _ in ivs]
    f1 = [t['fscore_1cm'] for t in ts if t.get('fscore_1cm')]
    f2 = [t['fscore_2cm'] for t in ts if t.get('fscore_2cm')]
    return '%d targets, %d analysed, |aerr|<=2: %d, inside: %d, median width %.2f, mean F1 %.4f min %.4f, mean F2 %.4f min %.4f' % (
        len(ts), len(al), ok, inside, st.median(w) if w else float('nan'), st.mean(f1), min(f1), st.mean(f2), min(f2))
def flight(i):
    ts = [r[i] for r in rows]
    loc = [t['localization_error_estimate_frame_m'] for t in ts
           if t.get('localization_error_estimate_frame_m') is not None]
    return 'frames dropped %d, searches after drops %d, localization <= 0.5 m %d of %d' % (
        sum(t.get('frames_dropped') or 0 for t in ts), sum(t.get('reacquisitions') or 0 for t in ts),
        sum(e <= 0.5 for e in loc), len(loc))
print('A:', tot(0)); print('B:', tot(1))
print('A:', flight(0)); print('B:', flight(1))
d = [(x['alpha_error_deg'], y['alpha_error_deg']) for x, y in rows if x.get('alpha_error_deg') is not None and y.get('alpha_error_deg') is not None]
if d:
    diffs = [abs(q - p) for p, q in d]
    print('paired |alpha A - alpha B|: median %.3f max %.3f over %d' % (st.median(diffs), max(diffs), len(d)))
    df = [y['fscore_1cm'] - x['fscore_1cm'] for x, y in rows if x.get('fscore_1cm') and y.get('fscore_1cm')]
    print('F1 B-A: mean %+.5f min %+.5f max %+.5f' % (st.mean(df), min(df), max(df)))
