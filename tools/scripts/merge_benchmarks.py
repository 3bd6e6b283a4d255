#!/usr/bin/env python3
"""Joins benchmark reports of one benchmark run as separate processes (for example one loop seed
per process, side by side on one GPU) into one report: their results in the order given, the
device of the first, the latest date and the command that produced them all.

    python3 tools/scripts/merge_benchmarks.py --output docs/benchmarks/NAME.json \\
        --command "THE COMMAND LINE THAT RAN THEM" PART.json [PART.json ...]

Plain python3, no packages beyond the standard library.
"""
import argparse
import json
import sys


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output", required=True, help="the joined report")
    parser.add_argument("--command", required=True, help="how the parts were produced")
    parser.add_argument("parts", nargs="+", help="reports of one benchmark")
    args = parser.parse_args()
    reports = []
    for path in args.parts:
        with open(path) as f:
            reports.append(json.load(f))
    names = {r.get("benchmark") for r in reports}
    devices = {r.get("device") for r in reports}
    if len(names) != 1:
        sys.exit("merge_benchmarks: the parts come from different benchmarks: %s" % sorted(names))
    if len(devices) != 1:
        sys.exit("merge_benchmarks: the parts ran on different devices: %s" % sorted(devices))
    seen = set()
    for path, report in zip(args.parts, reports):
        for row in report["results"]:
            key = (row["case"], row["metric"])
            if key in seen:
                sys.exit("merge_benchmarks: %s repeats case '%s', metric '%s' of an earlier part"
                         % (path, row["case"], row["metric"]))
            seen.add(key)
    merged = {
        "benchmark": reports[0]["benchmark"],
        "device": reports[0]["device"],
        "date": max(r["date"] for r in reports),
        "command": args.command,
        "results": [row for r in reports for row in r["results"]],
    }
    with open(args.output, "w") as f:
        f.write("{\n")
        for key in ("benchmark", "device", "date", "command"):
            f.write("  %s: %s,\n" % (json.dumps(key), json.dumps(merged[key])))
        f.write('  "results": [\n')
        rows = [json.dumps(row) for row in merged["results"]]
        f.write(",\n".join("    " + row for row in rows))
        f.write("\n  ]\n}\n")
    print("%d results of %d reports -> %s" % (len(rows), len(reports), args.output))


if __name__ == "__main__":
    main()
