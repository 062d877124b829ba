#!/usr/bin/env python3
"""Share of a `perf record` profile per source file and line of our code, through inlining.

Rayon inlines every parallel closure into `bridge_producer_consumer::helper`, so `perf report`
by symbol puts most of a mission's time under a handful of identical rayon names, and its
`--sort srcline` runs addr2line once per address (tens of minutes on the 97 MB binary). This
takes the sampled instruction addresses alone (no call graph needed), resolves them with one
`addr2line -i` process, and counts each sample under the innermost frame in our tree.

Usage:
    perf record -F 300 -o run.perf target/release/scarp simulate --out run/
    python3 docs/campaigns/tools/perf_by_source.py run.perf target/release/scarp [--top 40]
"""
import argparse
import collections
import pathlib
import re
import subprocess


def load_base(perf_data, binary):
    """(runtime address, file offset) of the binary's executable mapping."""
    events = subprocess.run(
        ["perf", "script", "-i", perf_data, "--show-mmap-events"],
        capture_output=True, text=True).stdout
    name = binary.rsplit("/", 1)[-1]
    for line in events.splitlines():
        if "MMAP" in line and "r-xp" in line and line.rstrip().endswith(name):
            m = re.search(r"\[(0x[0-9a-f]+)\((0x[0-9a-f]+)\) @ (0x[0-9a-f]+)", line)
            if m:
                return int(m.group(1), 16), int(m.group(3), 16)
    raise SystemExit(f"no executable mapping of {name} in {perf_data}")


def vaddr_of_offset(binary, offset):
    """The virtual address the ELF loads file offset `offset` at: through its executable LOAD
    segment (whose page-aligned mapping starts at or just below the segment's file offset)."""
    headers = subprocess.run(["readelf", "-lW", binary], capture_output=True, text=True).stdout
    for line in headers.splitlines():
        p = line.split()
        if p and p[0] == "LOAD" and "E" in p[6:-1]:
            return offset - int(p[1], 16) + int(p[2], 16)
    raise SystemExit(f"no executable LOAD segment in {binary}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("perf_data")
    ap.add_argument("binary")
    ap.add_argument("--top", type=int, default=40)
    # The build records absolute source paths: by default, the checkout this script lives in.
    here = pathlib.Path(__file__).resolve().parents[3]
    ap.add_argument("--tree", default=f"{here}/",
                    help="prefix of our sources in the debug info (default: this checkout)")
    args = ap.parse_args()
    runtime, offset = load_base(args.perf_data, args.binary)
    load_vaddr = vaddr_of_offset(args.binary, offset)
    samples = subprocess.run(
        ["perf", "script", "-i", args.perf_data, "-G", "-F", "ip,dso"],
        capture_output=True, text=True).stdout
    counts = collections.Counter()
    total = 0
    for line in samples.splitlines():
        p = line.split()
        if len(p) < 2:
            continue
        total += 1
        if args.binary.rsplit("/", 1)[-1] in p[1]:
            counts[int(p[0], 16) - runtime + load_vaddr] += 1
    addresses = list(counts)
    out = subprocess.run(["addr2line", "-a", "-f", "-i", "-C", "-e", args.binary],
                         input="\n".join(hex(a) for a in addresses),
                         capture_output=True, text=True).stdout.splitlines()
    frames, current, i = {}, None, 0
    while i < len(out):
        if out[i].startswith("0x"):
            current = int(out[i], 16)
            frames[current] = []
            i += 1
            continue
        frames[current].append(out[i + 1] if i + 1 < len(out) else "")
        i += 2
    by_file, by_line = collections.Counter(), collections.Counter()
    for address, n in counts.items():
        own = [loc.split(" ")[0] for loc in frames.get(address, []) if args.tree in loc]
        where = own[0].split(args.tree, 1)[1] if own else "(outside our tree)"
        by_file[where.rsplit(":", 1)[0]] += n
        by_line[where] += n
    print(f"{total} samples")
    for title, table in (("by file", by_file), ("by line", by_line)):
        print(f"--- {title}")
        for key, n in table.most_common(args.top):
            print(f"{100 * n / total:6.2f}%  {key}")


if __name__ == "__main__":
    main()
