#!/usr/bin/env python3
"""How an α_min interval rule would have done on recorded scans.

Reads the `READINGS` and `FEATURES` lines of `examples/contact_diagnosis.rs` (a campaign folder,
or `--mesh` for one scan), drops repeated scans (the same readings), and for each rule prints
how often the truth falls inside, the median width, and how many point estimates lie within 2°,
above +2° and +3°, and below -2°.

A rule is (plane scale s, edge shrink d metres, relative margin m, margin a degrees), as in
`fragility::scan::analyze_closed_scan`: the readings at the plane moved by s times the ensemble's
offset (linear between its readings), each also with its contact shrunk by d, widened by m and a.

usage: interval_calibration.py FILE... [--rule s,d,m,a]...   (default: the shipped rule 1,0.01,0.05,1)
"""
import math
import sys


def load(paths):
    rows, feats, seen, out = {}, {}, set(), []
    for path in paths:
        for line in open(path):
            f = line.split()
            if f and f[0] == 'READINGS':
                rows[f[1]] = (float(f[2]), [float(x) for x in f[3:]])
            elif f and f[0] == 'FEATURES':
                feats[f[1]] = float(f[-1])
    for label, (truth, readings) in rows.items():
        key = tuple(round(x, 3) for x in readings if x == x)
        if key not in seen:
            seen.add(key)
            out.append((label, truth, readings, feats.get(label, 0.7)))
    return out


def shrunk(alpha_deg, com_height_m, shrink_m):
    d = math.tan(math.radians(alpha_deg)) * com_height_m - shrink_m
    return math.degrees(math.atan2(max(d, 0.0), com_height_m))


def scaled(group, s):
    """The readings of one 36-reading group at the plane offsets scaled by s (triplets -, 0, +)."""
    out = []
    for j in range(0, len(group), 3):
        low, mid, high = group[j:j + 3]
        out += [x for x in (mid + s * (low - mid), mid, mid + s * (high - mid)) if x == x]
    return out


def evaluate(data, s, d, m, a):
    inside, widths, within, over2, over3, under2, misses = 0, [], 0, 0, 0, 0, []
    for label, truth, readings, com_height in data:
        groups = [readings[i:i + 36] for i in range(0, len(readings), 36)]
        first = sorted(scaled(groups[0], s))
        point = first[(len(first) - 1) // 2]
        values = [x for g in groups for x in scaled(g, s)]
        values += [shrunk(x, com_height, d) for x in values] if d > 0 else []
        low = max(min(min(values), point) * (1 - m) - a, 0.0)
        high = max(max(values), point) * (1 + m) + a
        ok = low <= truth <= high
        inside += ok
        widths.append(high - low)
        within += abs(point - truth) <= 2.0
        over2 += point - truth > 2.0
        over3 += point - truth > 3.0
        under2 += point - truth < -2.0
        if not ok:
            misses.append(f'{label}: truth {truth:.2f} outside [{low:.2f}, {high:.2f}], estimate {point:.2f}')
    widths.sort()
    n = len(data)
    print(f'rule s={s} d={d} m={m} a={a}: {n} scans, truth inside {inside} ({100 * inside / n:.0f}%), '
          f'median width {widths[n // 2]:.2f}°, |err| <= 2° {within}, over +2° {over2}, '
          f'over +3° {over3}, under -2° {under2}')
    for miss in misses:
        print('   ', miss)


def main():
    args, rules, files = sys.argv[1:], [], []
    while args:
        arg = args.pop(0)
        if arg == '--rule':
            rules.append(tuple(float(x) for x in args.pop(0).split(',')))
        else:
            files.append(arg)
    data = load(files)
    for rule in rules or [(1.0, 0.01, 0.05, 1.0)]:
        evaluate(data, *rule)


if __name__ == '__main__':
    main()
