#!/usr/bin/env python3
"""Compares same-run A/B benchmark JSON files (tools/device/ab_tsdf.sh writes base_N.json and
new_N.json): for each case, the median integration time of every run, the median of those
medians per side, and the ratio new / base.

    python3 tools/scripts/ab_table.py DIR [metric]
"""
import glob
import json
import os
import statistics
import sys


def load(paths, metric):
    runs = []
    for path in sorted(paths):
        with open(path) as f:
            runs.append({r["case"]: r["value"] for r in json.load(f)["results"] if r["metric"] == metric})
    return runs


def main(directory, metric="median integration time"):
    base = load(glob.glob(os.path.join(directory, "base_*.json")), metric)
    new = load(glob.glob(os.path.join(directory, "new_*.json")), metric)
    if not base or not new:
        sys.exit(f"no base_*.json / new_*.json in {directory}")
    print(f"| case | base runs | new runs | base | new | new / base |")
    print("|---|---|---|---:|---:|---:|")
    for case in base[0]:
        b = [run[case] for run in base if case in run]
        n = [run[case] for run in new if case in run]
        if not b or not n:
            continue
        mb, mn = statistics.median(b), statistics.median(n)
        print(f"| {case} | {' / '.join(f'{v:.3f}' for v in b)} | {' / '.join(f'{v:.3f}' for v in n)} "
              f"| {mb:.3f} | {mn:.3f} | {mn / mb:.2f} |")


if __name__ == "__main__":
    main(*sys.argv[1:])
