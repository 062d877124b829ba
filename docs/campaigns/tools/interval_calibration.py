#!/usr/bin/env python3
"""How α_min intervals did, or would have done, on recorded scans.

Reads the `READINGS`, `INTERVAL`, `UNSEEN` and `FEATURES` lines of `examples/contact_diagnosis.rs`
(see `collect_readings.sh`) and drops repeated scans (the same readings). Then, for the shipped
interval (the `INTERVAL` lines) and for each rule given, prints how often the truth falls inside,
the median width, and how many point estimates lie within 2°, above +2° and +3°, and below -2°,
with the misses.

Rules:
- `--quadrature k,margin,ratio`: `fragility::scan::analyze_closed_scan`'s rule (session 22) with
  its sources scaled by k, `margin` degrees for `interval_margin_deg` and the unseen patches'
  bulge ratio (0.25, 0.5 or 1, the ratios the `UNSEEN` lines hold; 0 leaves the source out);
  the shipped rule is 1,1.5,0.5 less the perturbation study, which the readings do not hold (a
  few hundredths of a degree);
- `--envelope s,d,m,a`: the rule shipped before session 22: the envelope of the readings at the
  plane moved by s times the ensemble's offset, each also with its contact shrunk by d metres,
  widened by the fraction m and by a degrees.

usage: interval_calibration.py FILE... [--quadrature k,m,r]... [--envelope s,d,m,a]...
"""
import math
import sys

RATIOS = (0.25, 0.5, 1.0)


def load(paths):
    rows, extra, seen, out = {}, {}, set(), []
    for path in paths:
        for line in open(path):
            f = line.split()
            if len(f) < 2:
                continue
            if f[0] == 'READINGS':
                rows[f[1]] = (float(f[2]), [float(x) for x in f[3:]])
            elif f[0] in ('INTERVAL', 'UNSEEN', 'FEATURES'):
                extra.setdefault(f[1], {})[f[0]] = f[2:]
    for label, (truth, readings) in rows.items():
        key = tuple(round(x, 3) for x in readings if x == x)
        if key in seen:
            continue
        seen.add(key)
        e = extra.get(label, {})
        out.append({
            'label': label, 'truth': truth, 'readings': readings,
            'com_height': float(e['FEATURES'][-1]) if 'FEATURES' in e else 0.7,
            'shipped': [float(x) for x in e['INTERVAL'][1:4]] if 'INTERVAL' in e else None,
            'unseen': [float(x) for x in e['UNSEEN'][2:]] if 'UNSEEN' in e else [0.0] * 6,
        })
    return out


def shrunk(alpha_deg, com_height_m, shrink_m):
    d = math.tan(math.radians(alpha_deg)) * com_height_m - shrink_m
    return math.degrees(math.atan2(max(d, 0.0), com_height_m))


def median(values):
    values = sorted(values)
    return values[(len(values) - 1) // 2] if values else 0.0


def groups_of(readings):
    """The 36-reading groups: with the support outline's gaps interpolated, then open."""
    return [readings[i:i + 36] for i in range(0, len(readings), 36)]


def quadrature(scan, k, margin, ratio):
    """(point, low, high) under the quadrature rule."""
    groups = groups_of(scan['readings'])
    runs = [groups[0][j:j + 3] for j in range(0, 36, 3)]
    point = median(x for x in groups[0] if x == x)
    full = [r for r in runs if all(x == x for x in r)]
    mids = [r[1] for r in runs if r[1] == r[1]]
    sources = [
        (median(r[1] - min(r) for r in full), median(max(r) - r[1] for r in full)),
        (point - min(mids + [point]), max(mids + [point]) - point),
        (point - shrunk(point, scan['com_height'], 0.01), 0.0),
        (margin, margin),
    ]
    if len(groups) > 1:
        sources.append((0.0, max(0.0, median(x for x in groups[1] if x == x) - point)))
    if ratio > 0:
        i = RATIOS.index(ratio)
        sources.append((scan['unseen'][2 * i], scan['unseen'][2 * i + 1]))
    below = k * math.sqrt(sum(b * b for b, _ in sources))
    above = k * math.sqrt(sum(a * a for _, a in sources))
    return point, max(point - below, 0.0), point + above


def envelope(scan, s, d, m, a):
    """(point, low, high) under the envelope rule."""
    def scaled(group):
        out = []
        for j in range(0, len(group), 3):
            low, mid, high = group[j:j + 3]
            out += [x for x in (mid + s * (low - mid), mid, mid + s * (high - mid)) if x == x]
        return out

    groups = groups_of(scan['readings'])
    point = median(scaled(groups[0]))
    values = [x for g in groups for x in scaled(g)]
    values += [shrunk(x, scan['com_height'], d) for x in values] if d > 0 else []
    return (point, max(min(min(values), point) * (1 - m) - a, 0.0),
            max(max(values), point) * (1 + m) + a)


def score(name, data, interval):
    inside, widths, within, over2, over3, under2, misses = 0, [], 0, 0, 0, 0, []
    for scan in data:
        point, low, high = interval(scan)
        truth = scan['truth']
        ok = low <= truth <= high
        inside += ok
        widths.append(high - low)
        within += abs(point - truth) <= 2.0
        over2 += point - truth > 2.0
        over3 += point - truth > 3.0
        under2 += point - truth < -2.0
        if not ok:
            misses.append(f"{scan['label']}: truth {truth:.2f} outside [{low:.2f}, {high:.2f}], "
                          f"estimate {point:.2f}")
    n = len(data)
    print(f'{name}: {n} scans, truth inside {inside} ({100 * inside / n:.0f}%), '
          f'median width {sorted(widths)[n // 2]:.2f}°, |err| <= 2° {within}, over +2° {over2}, '
          f'over +3° {over3}, under -2° {under2}')
    for miss in misses:
        print('   ', miss)


def main():
    args, rules, files = sys.argv[1:], [], []
    while args:
        a = args.pop(0)
        if a in ('--quadrature', '--envelope'):
            rules.append((a[2:], [float(x) for x in args.pop(0).split(',')]))
        else:
            files.append(a)
    data = load(files)
    shipped = [scan for scan in data if scan['shipped']]
    if shipped:
        score('shipped (INTERVAL lines)', shipped, lambda scan: scan['shipped'])
    for kind, params in rules:
        rule = quadrature if kind == 'quadrature' else envelope
        score(f'{kind} {",".join(map(str, params))}', data, lambda scan: rule(scan, *params))


if __name__ == '__main__':
    main()
