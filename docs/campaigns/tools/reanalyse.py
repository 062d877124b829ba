#!/usr/bin/env python3
"""Re-runs the fragility analysis on the saved meshes of finished campaigns and tabulates it.

    python3 docs/campaigns/tools/reanalyse.py [--bin CONTACT_DIAGNOSIS] [--config FRAGILITY_TOML]
        [--jobs N] [--models] CAMPAIGN_DIR...

`CONTACT_DIAGNOSIS` is the `contact_diagnosis` example of the build under test
(`cargo build --release --example contact_diagnosis`; default
`target/release/examples/contact_diagnosis`). The analysis is deterministic per mesh, so two
builds (or two configurations) compared on the same campaign folders are an exact pairing: the
flights are the same, only the analysis differs. The mission's own figures equal these for the
build that flew.

Prints, over every mesh of a target (mapped or not) that `mission.json` names:
- the totals: targets, refused, |α error| ≤ 2° (a refusal counts as a miss), α over by more
  than 3°, the truth inside the interval and the interval's median width;
- per rock (world and id): n, median, least and greatest error, coverage, median width;
- the refusals, counted per rock and kind of reason;
- with `--models`, per profile model and fit window (the 12 readings at the measured plane of
  `ContactHypothesis::ensemble`), the share of scans read within 2°.

A scan met in several campaign folders (linked or copied runs) is counted once: an analysed
one by its label and interval, a refused one by its label and reason.
"""
import argparse
import collections
import re
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

MODELS = [f"{m}-skip{s}-fit{f}" for m in ("r2", "r") for s in (0, 1) for f in (3, 4, 6)]


def refusal_kind(reason):
    """A refusal's kind: its text without the error's prefixes, every figure replaced by N."""
    reason = reason.removeprefix("fragility: ").removeprefix("degenerate geometry: ")
    return re.sub(r"\d+(\.\d+)?", "N", reason)


def run(binary, config, campaign):
    args = [binary, campaign] + ([config] if config else [])
    return subprocess.run(args, capture_output=True, text=True, check=True).stdout


def parse(text):
    """{label: (truth, α, low, high)}, {label: readings} and {label: (truth, reason)}."""
    analysed, readings, refused = {}, {}, {}
    for line in text.splitlines():
        if line.startswith("READINGS"):
            t = line.split()
            readings[t[1]] = [float(x) for x in t[3:39]]
        elif line.startswith("INTERVAL"):
            t = line.split()
            analysed[t[1]] = tuple(map(float, t[2:6]))
        elif " refused: " in line and "|" in line:
            label = line.split("|")[0].strip().replace(" ", "_")
            refused[label] = (float(line.split("|")[1].split()[0]), line.split(" refused: ")[1])
    return analysed, readings, refused


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--bin", default="target/release/examples/contact_diagnosis")
    p.add_argument("--config", default="")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--models", action="store_true")
    p.add_argument("campaigns", nargs="+")
    a = p.parse_args()
    with ThreadPoolExecutor(a.jobs) as pool:
        outputs = list(pool.map(lambda c: run(a.bin, a.config, c), a.campaigns))
    rows, seen = [], set()
    for text in outputs:
        analysed, readings, refused = parse(text)
        for label, (truth, alpha, low, high) in analysed.items():
            key = (label, alpha, low, high)
            if key not in seen:
                seen.add(key)
                rows.append((label, truth, alpha, low, high, readings.get(label), None))
        for label, (truth, reason) in refused.items():
            if (label, reason) not in seen:
                seen.add((label, reason))
                rows.append((label, truth, None, None, None, None, reason))
    ok = [r for r in rows if r[2] is not None]
    if not ok:
        sys.exit("no analysed target")
    within = sum(abs(r[2] - r[1]) <= 2 for r in ok)
    over = sum(r[2] - r[1] > 3 for r in ok)
    cover = sum(r[3] <= r[1] <= r[4] for r in ok)
    width = statistics.median(r[4] - r[3] for r in ok)
    print(f"targets {len(rows)}, refused {len(rows) - len(ok)}; |α err| ≤ 2° {within} "
          f"({within / len(rows):.1%} of all, {within / len(ok):.1%} of analysed); "
          f"over 3° {over}; truth in interval {cover}/{len(ok)} ({cover / len(ok):.1%}), "
          f"median width {width:.2f}°")
    by_rock = collections.defaultdict(list)
    for r in ok:
        by_rock[re.sub(r"_seed-\d+", "", r[0])].append(r)
    for rock, rs in sorted(by_rock.items()):
        errors = [r[2] - r[1] for r in rs]
        covered = sum(r[3] <= r[1] <= r[4] for r in rs)
        print(f"  {rock[:56]:56s} n {len(rs):3d}  error median {statistics.median(errors):+.2f} "
              f"[{min(errors):+.2f}, {max(errors):+.2f}]  cover {covered}/{len(rs)}  "
              f"width {statistics.median(r[4] - r[3] for r in rs):.2f}")
    # Refusals count as misses in the totals; where they fall, and why, is what to fix next.
    refusals = collections.Counter()
    for r in rows:
        if r[2] is None:
            kind = refusal_kind(r[6])
            refusals[(re.sub(r"_seed-\d+", "", r[0])[:56], kind[:70])] += 1
    for (rock, kind), n in sorted(refusals.items(), key=lambda kv: (-kv[1], kv[0])):
        print(f"  refused {n:3d}  {rock:56s} {kind}")
    if a.models:
        with_readings = [r for r in ok if r[5]]
        for i, name in enumerate(MODELS):
            # The reading at the measured plane: the middle of each (−, 0, +) offset triple.
            errors = [r[5][3 * i + 1] - r[1] for r in with_readings if r[5][3 * i + 1] == r[5][3 * i + 1]]
            share = sum(abs(e) <= 2 for e in errors) / max(len(errors), 1)
            print(f"  reading {name:14s} within 2° {share:.1%}  median {statistics.median(errors):+.2f}  "
                  f"over 3° {sum(e > 3 for e in errors)}")


if __name__ == "__main__":
    main()
