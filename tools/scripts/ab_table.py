#!/usr/bin/env python3
"""Compares the benchmark JSON files of several builds run in turn on one machine (so that all
see the same machine state): for each case, the median
integration time of every run, the median of those medians per side, and its ratio to the
first side. tools/device/ab_tsdf.sh writes base_N.json and new_N.json (the default sides);
tools/device/ab_trees.sh writes NAME_N.json for the sides it names.

    python3 tools/scripts/ab_table.py DIR [--sides A,B,...] [--metric METRIC]
"""
import argparse
import glob
import json
import os
import re
import statistics
import sys


def load(directory, side, metric):
    runs = []
    paths = [p for p in glob.glob(os.path.join(directory, f"{side}_*.json"))
             if re.fullmatch(re.escape(side) + r"_\d+\.json", os.path.basename(p))]
    for path in sorted(paths):
        with open(path) as f:
            runs.append({r["case"]: r["value"] for r in json.load(f)["results"] if r["metric"] == metric})
    return runs


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("directory")
    parser.add_argument("metric_positional", nargs="?", help=argparse.SUPPRESS)
    parser.add_argument("--sides", default="base,new")
    parser.add_argument("--metric", default="median integration time")
    args = parser.parse_args()
    metric = args.metric_positional or args.metric
    sides = args.sides.split(",")
    runs = {side: load(args.directory, side, metric) for side in sides}
    missing = [side for side in sides if not runs[side]]
    if missing:
        sys.exit(f"no runs of {', '.join(missing)} in {args.directory}")
    first = sides[0]
    header = " | ".join(f"{side} runs" for side in sides)
    medians = " | ".join(sides)
    ratios = " | ".join(f"{side} / {first}" for side in sides[1:])
    print(f"| case | {header} | {medians} | {ratios} |")
    print("|---|" + "---|" * len(sides) + "---:|" * len(sides) + "---:|" * (len(sides) - 1))
    for case in runs[first][0]:
        values = {side: [run[case] for run in runs[side] if case in run] for side in sides}
        if any(not v for v in values.values()):
            continue
        median = {side: statistics.median(values[side]) for side in sides}
        cells = " | ".join(" / ".join(f"{v:.3f}" for v in values[side]) for side in sides)
        mids = " | ".join(f"{median[side]:.3f}" for side in sides)
        rel = " | ".join(f"{median[side] / median[first]:.2f}" for side in sides[1:])
        print(f"| {case} | {cells} | {mids} | {rel} |")


if __name__ == "__main__":
    main()
