#!/usr/bin/env python3
# Per target: the estimate-frame error of several centre estimators computed from the filter's
# points (targets/ID/points.ply): mean (C_e today), median, and the mid-range of quantiles.
# usage: centre_estimators.py CAMPAIGN_DIR [...]
import math, sys
from localization_spread import flown_targets
def q(xs, f):
    s = sorted(xs); k = f * (len(s) - 1); i = int(k); t = k - i
    return s[i] if i + 1 >= len(s) else s[i] * (1 - t) + s[i + 1] * t
est = {
 'mean': lambda a: sum(a) / len(a),
 'median': lambda a: q(a, 0.5),
 'mid05': lambda a: (q(a, 0.05) + q(a, 0.95)) / 2,
 'mid10': lambda a: (q(a, 0.10) + q(a, 0.90)) / 2,
 'mid25': lambda a: (q(a, 0.25) + q(a, 0.75)) / 2,
 'mid01': lambda a: (q(a, 0.01) + q(a, 0.99)) / 2,
}
errs = {k: [] for k in est}; vs = {k: [] for k in est}
for d0 in sys.argv[1:]:
    for d, t, c, e, pts in flown_targets(d0):
        row = []
        for k, f in est.items():
            L = [f([p[a] for p in pts]) for a in range(3)]
            off = [L[a] - c[a] - e[a] for a in range(3)]
            n = math.sqrt(sum(x * x for x in off))
            errs[k].append(n); vs[k].append(off[2])
            row.append('%s %.2f(%+.2f)' % (k, n, off[2]))
        print('%-34s %2d ' % (d.split('/runs/')[0].split('/')[-1] + '/' + d.split('runs/')[1], t['id']) + ' '.join(row))
print()
for k in est:
    a = errs[k]; n = len(a); s = sorted(a)
    v = vs[k]; mv = sum(v) / n; sv = math.sqrt(sum((x - mv) ** 2 for x in v) / n)
    print('%-7s n %d  <=0.5: %d  median %.2f  worst %.2f  v mean %+.2f sd %.2f' % (k, n, sum(x <= 0.5 for x in a), s[n // 2], s[-1], mv, sv))
