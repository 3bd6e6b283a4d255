#!/usr/bin/env python3
"""Prints the latest benchmark tables (docs/benchmarks/*.json) as Markdown, with the command,
device and date of each run, for pasting into the documentation:

    python3 tools/scripts/benchmark_tables.py docs/benchmarks/*.json
"""
import json
import sys


def number(value):
    if value is None:
        return "n/a"
    if float(value).is_integer() and abs(value) < 1e15:
        return str(int(value))
    if abs(value) >= 100:
        return f"{value:.1f}"
    if abs(value) >= 1:
        return f"{value:.3f}"
    return f"{value:.4g}"


def main(paths):
    for path in paths:
        with open(path) as f:
            run = json.load(f)
        name = run.get("benchmark", path)
        print(f"### {name}\n")
        print(f"- command: `{run['command']}`")
        print(f"- device: {run['device']}")
        print(f"- date: {run['date']}\n")
        print("| case | metric | value | unit |")
        print("|---|---|---:|---|")
        for row in run["results"]:
            print(f"| {row['case']} | {row['metric']} | {number(row['value'])} | {row['unit']} |")
        print()


if __name__ == "__main__":
    main(sys.argv[1:])
