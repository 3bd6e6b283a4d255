#!/usr/bin/env python3
"""Rewrites the generated tables of docs/performance.md from the benchmark reports in
docs/benchmarks/*.json (written by the benchmarks themselves: {"benchmark", "device", "date",
"command", "results": [{"case", "metric", "value", "unit"}]}).

    python3 tools/scripts/performance_tables.py [--check] [--doc docs/performance.md]

Each generated block sits between two marker lines,

    <!-- generated: NAME -->
    ...
    <!-- end generated: NAME -->

and only the text between them is replaced; everything else in the document is left as written.
--check rewrites nothing and exits with status 1 when a block is out of date. Plain python3, no
packages beyond the standard library.
"""
import argparse
import glob
import json
import os
import re
import shlex
import sys

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BENCHMARKS = os.path.join(REPO, "docs", "benchmarks")

# Options whose values are where a run wrote its output or found its input on one machine; they
# are left out of the commands shown, since they do not change what is measured.
LOCAL_PATH_OPTIONS = {"--output", "--data", "--data-dir", "--json", "--trajectory",
                      "--odometry-trajectory", "--mesh", "--trajectories-dir", "--graph", "--map"}

TSDF_MS = "median integration time"
INCREMENTAL = "incremental update (median)"
SOLVE = "solve time (median)"

LOOPS = "loop_closure.json"
LOOPS_LOOSE = "loop_closure_loose_sigmas.json"
LOOPS_PER_LINK = "loop_closure_per_link_noise.json"
LOOP_ATE_LIMIT_M = 0.5


def loop_flights(report):
    """The drifting flights of a loops report (cases "simulated loops seed N, P % drift")."""
    cases = dict.fromkeys(row["case"] for row in report["results"])
    return [case for case in cases if case.startswith("simulated loops seed ")]


def loop_flights_within_limit(reports, name):
    report = reports.get(name)
    if report is None:
        return None
    ates = [lookup(reports, (name, case, "ATE RMSE covoxslam")) for case in loop_flights(report)]
    return sum(1 for ate in ates if ate is not None and ate <= LOOP_ATE_LIMIT_M)


def loop_wrong_closures(reports, name):
    report = reports.get(name)
    if report is None:
        return None
    cases = dict.fromkeys(row["case"] for row in report["results"])
    wrong = [lookup(reports, (name, case, "loop closures wrong by > 1 m or 5 deg"))
             for case in cases]
    return sum(w for w in wrong if w is not None)


def no_drift_difference(reports, name, reference):
    """The flight without drift's ATE minus the reference's: the run without place recognition's
    ("closures") or the odometry's ("odometry")."""
    ours = lookup(reports, (name, "simulated loops no drift", "ATE RMSE covoxslam"))
    if reference == "closures":
        other = lookup(reports, (name, "simulated loops no drift, no place recognition",
                                 "ATE RMSE covoxslam"))
    else:
        other = lookup(reports, (name, "simulated loops no drift", "ATE RMSE odometry"))
    return None if ours is None or other is None else ours - other


def sim_flight_ates(reports, name):
    """ATE of every simulated 200 s flight ("simulated flight seed N") of a report."""
    report = reports.get(name)
    if report is None:
        return []
    cases = dict.fromkeys(row["case"] for row in report["results"])
    ates = [lookup(reports, (name, case, "ATE RMSE covoxslam"))
            for case in cases if case.startswith("simulated flight seed ")]
    return [ate for ate in ates if ate is not None]


def sim_flights_mean(reports, name):
    ates = sim_flight_ates(reports, name)
    return sum(ates) / len(ates) if ates else None


def sim_flights_worst(reports, name):
    ates = sim_flight_ates(reports, name)
    return max(ates) if ates else None


def cases_mean(reports, name, prefix, metric):
    """The mean of `metric` over the cases whose name starts with `prefix`."""
    report = reports.get(name)
    if report is None:
        return None
    cases = dict.fromkeys(row["case"] for row in report["results"])
    values = [lookup(reports, (name, case, metric)) for case in cases if case.startswith(prefix)]
    values = [v for v in values if v is not None]
    return sum(values) / len(values) if values else None


def above_odometry(reports, name, case):
    """How much farther from the reference covoxslam ends than the odometry it was given."""
    ours = lookup(reports, (name, case, "distance to reference RMSE covoxslam"))
    odometry = lookup(reports, (name, case, "distance to reference RMSE odometry"))
    return None if ours is None or odometry is None else ours - odometry


def derived_goal(label, name, figure, *args):
    """A goals selector for a figure derived from a report: (label, (file, function of the reports))."""
    return (label, (name, lambda reports: figure(reports, name, *args)))


# The project's goals. A row is met when every selected figure is on the right side of its
# threshold. Selector: (report file, case, metric), or (report file, function of the reports)
# for a figure derived from several rows.
GOALS = [
    ("hash table insert, GPU, load 0.85", ">=", 1000, "Mkeys/s",
     [("", ("hash_table.json", "cuda load 0.85", "insert (activate)"))]),
    ("hash table find, GPU, load 0.85", ">=", 2000, "Mkeys/s",
     [("", ("hash_table.json", "cuda load 0.85", "find"))]),
    ("hash table insert, CPU twin, load 0.5 / 0.7 / 0.85", ">=", 20, "Mkeys/s",
     [("0.5", ("hash_table_cpu_2core.json", "cpu load 0.5", "insert (activate)")),
      ("0.7", ("hash_table_cpu_2core.json", "cpu load 0.7", "insert (activate)")),
      ("0.85", ("hash_table_cpu_2core.json", "cpu load 0.85", "insert (activate)"))]),
    ("TSDF OS1-64 0.2 m, 16 m rays, merged, GPU", "<=", 0.5, "ms/scan",
     [("", ("tsdf.json", "cuda OS1-64 0.2 m, 16 m rays, merged", TSDF_MS))]),
    ("TSDF 7-Scenes 5 cm, colour, carving, GPU", "<=", 0.1, "ms/frame",
     [("", ("tsdf.json", "cuda 7-Scenes 5 cm colour carving", TSDF_MS))]),
    ("TSDF 7-Scenes 2 cm, colour, carving, GPU", "<=", 0.27, "ms/frame",
     [("", ("tsdf.json", "cuda 7-Scenes 2 cm colour carving", TSDF_MS))]),
    ("TSDF OS1-64 0.2 m, merged, CPU twin", "<=", 50, "ms/scan",
     [("", ("tsdf_cpu_2core.json", "cpu OS1-64 0.2 m, 16 m rays, merged", TSDF_MS))]),
    ("ESDF incremental, OS1-64 0.2 m, GPU", "<=", 1.0, "ms/scan",
     [("", ("esdf.json", "cuda OS1-64 0.2 m, ESDF 2 m", INCREMENTAL))]),
    ("ESDF incremental 3-D, 7-Scenes 5 cm, GPU", "<=", 0.5, "ms/frame",
     [("", ("esdf.json", "cuda 7-Scenes 5 cm, ESDF 2 m", INCREMENTAL))]),
    ("mesh incremental, 7-Scenes 5 cm, GPU", "<=", 0.25, "ms/frame",
     [("", ("mesh.json", "cuda 7-Scenes 5 cm, ESDF 2 m", INCREMENTAL))]),
    ("offline runner, simulated flight (256 columns), CPU twin", ">=", 1.0, "x real time",
     [("", ("accuracy.json", "simulated flight seed 1", "real-time factor"))]),
    ("offline runner, 1024-column flight, GPU", ">=", 10.0, "x real time",
     [("", ("pipeline.json", None, "real-time factor"))]),
    ("30-minute mission, 1024 columns, GPU (scans simulated in process / read from a bag)", ">=",
     50.0, "x real time",
     [("in process", ("mission_gpu.json", "mission-1800s-1024col", "real-time factor")),
      ("bag", ("mission_gpu_bag.json", "mission-1800s-1024col-bag", "real-time factor"))]),
    ("60-minute mission, 256 columns, CPU twin", ">=", 1.0, "x real time",
     [("", ("mission_cpu.json", "simulated mission 3600 s, seed 1, 256 columns",
            "real-time factor"))]),
    ("distorted 200 s flights, seeds 1-15, shipped defaults: mean ATE", "<=", 0.25, "m",
     [derived_goal("", "accuracy.json", sim_flights_mean)]),
    ("distorted 200 s flights, seeds 1-15, shipped defaults: worst ATE", "<=", 0.5, "m",
     [derived_goal("", "accuracy.json", sim_flights_worst)]),
    ("7-Scenes ATE from 0.3 m-drifting odometry", "<=", 0.05, "m",
     [("", ("accuracy.json", "7-Scenes redkitchen", "ATE RMSE covoxslam"))]),
    ("7-Scenes redkitchen-long, drift seeds 1-5: mean ATE", "<=", 0.03, "m",
     [derived_goal("", "accuracy.json", cases_mean, "7-Scenes redkitchen-long seed",
                "ATE RMSE covoxslam")]),
    ("real LiDAR with good odometry: distance to reference above the odometry's", "<=", 0.01, "m",
     [derived_goal("KITTI 07", "accuracy.json", above_odometry, "KITTI 07 keyframes no drift"),
      derived_goal("HKU-2", "accuracy.json", above_odometry, "Livox HKU-2 as recorded")]),
    ("loop flights (1980 m, odometry >= 10 m off) with ATE <= 0.5 m (experiment: loops.yaml, not the shipped defaults)", ">=", 5, "seeds",
     [derived_goal("", LOOPS, loop_flights_within_limit)]),
    ("wrong place-recognition closures on the loop flights (experiment: loops.yaml, not the shipped defaults)", "<=", 0, "closures",
     [derived_goal("", LOOPS, loop_wrong_closures)]),
    ("loop flight without drift: ATE above the odometry's (experiment: loops.yaml, not the shipped defaults)", "<=", 0.05, "m",
     [derived_goal("", LOOPS, no_drift_difference, "odometry")]),
    ("loop flight without drift: ATE added by the closures (experiment: loops.yaml, not the shipped defaults)", "<=", 0.05, "m",
     [derived_goal("", LOOPS, no_drift_difference, "closures")]),
]

REGISTRATION_GRAPHS = [("50", "reg n=50 (146 pairs, 297k points)"),
                       ("200", "reg n=200 (596 pairs, 1213k points)"),
                       ("1000", "reg n=1000 (2996 pairs, 6098k points)")]

# Published figures of the peers (their own documentation and papers; the hardware is theirs),
# next to this project's figure for the closest case.
PEERS = [
    ("TSDF, RGB-D frame, 5 cm", ("tsdf.json", "cuda 7-Scenes 5 cm colour carving", TSDF_MS),
     "ms", "nvblox (projective, depth only): Replica 0.5 ms on an RTX 3090, 0.1 ms on an RTX 5090, "
     "0.8 ms on an AGX Orin; voxblox merged (CPU, i7-4810MQ, cow-and-lady) 112 ms, fast 23 ms"),
    ("TSDF, RGB-D frame, 2 cm", ("tsdf.json", "cuda 7-Scenes 2 cm colour carving", TSDF_MS),
     "ms", "voxblox merged (CPU) 527 ms, fast 63 ms"),
    ("TSDF, LiDAR scan, 0.2 m voxels, 50 m rays",
     ("tsdf.json", "cuda KITTI HDL-64 0.2 m, 50 m rays, merged", TSDF_MS),
     "ms", "voxblox fast (CPU), KITTI Velodyne: 44 ms"),
    ("TSDF, LiDAR scan, 0.2 m voxels, CPU twin",
     ("tsdf_cpu_2core.json", "cpu KITTI HDL-64 0.2 m, 50 m rays, merged", TSDF_MS),
     "ms", "voxblox fast (CPU), KITTI Velodyne: 44 ms"),
    ("ESDF update, RGB-D, 5 cm", ("esdf.json", "cuda 7-Scenes 5 cm, ESDF 2 m", INCREMENTAL),
     "ms", "nvblox: 0.8 ms (RTX 3090), 0.3 ms (RTX 5090), 1.7 ms (AGX Orin)"),
    ("mesh update, RGB-D, 5 cm", ("mesh.json", "cuda 7-Scenes 5 cm, ESDF 2 m", INCREMENTAL),
     "ms", "nvblox: 0.7 ms (RTX 3090), 0.3 ms (RTX 5090), 2.3 ms (AGX Orin)"),
    ("pose graph of 50 submaps with dense registration terms",
     ("backend.json", "reg n=50 (146 pairs, 297k points) cuda block-Jacobi", SOLVE), "ms",
     "voxgraph's solver, Ceres SPARSE_SCHUR with 4 threads: see the backend table"),
]


def number(value):
    if value is None:
        return "n/a"
    if abs(value) < 1e-12:  # rounding noise of a zero
        return "0"
    if float(value).is_integer() and abs(value) < 1e15:
        return str(int(value))
    if abs(value) >= 100:
        return f"{value:.1f}"
    if abs(value) >= 10:
        return f"{value:.2f}"
    if abs(value) >= 1:
        return f"{value:.3f}"
    return f"{value:#.3g}"


def with_unit(value, unit):
    return "n/a" if value is None else number(value) + unit


def load_reports():
    reports = {}
    for path in sorted(glob.glob(os.path.join(BENCHMARKS, "*.json"))):
        with open(path) as f:
            reports[os.path.basename(path)] = json.load(f)
    return reports


def lookup(reports, selector):
    """The value of (file, case, metric); case None takes the report's first case."""
    name, case, metric = selector
    report = reports.get(name)
    if report is None:
        return None
    for row in report["results"]:
        if (case is None or row["case"] == case) and row["metric"] == metric:
            return row["value"]
    return None


def shown_command(command):
    """The recorded command with machine-local paths left out: the program from build/, no
    output or data locations, absolute input files by their last two path components."""
    try:
        words = shlex.split(command)
    except ValueError:
        return command
    if not words:
        return command
    # A script (or one run with environment settings) is shown as it was given.
    if "=" in words[0] or words[0].endswith(".sh"):
        return command
    shown = ["build/" + os.path.basename(words[0])]
    skip = False
    for word in words[1:]:
        if skip:
            skip = False
            continue
        if word in LOCAL_PATH_OPTIONS:
            skip = True
            continue
        if os.path.isabs(word):
            word = os.path.join(*word.split(os.sep)[-2:])
        shown.append(shlex.quote(word))
    return " ".join(shown)


def goals_table(reports):
    lines = ["| goal | target | measured | verdict | report |", "|---|---|---|---|---|"]
    for what, sense, threshold, unit, selectors in GOALS:
        figures, verdicts, files = [], [], []
        for label, selector in selectors:
            value = selector[1](reports) if callable(selector[1]) else lookup(reports, selector)
            files.append(selector[0])
            if value is None:
                figures.append(f"{label} not recorded".strip())
                verdicts.append(None)
                continue
            met = value >= threshold if sense == ">=" else value <= threshold
            figures.append(f"{label}: {number(value)}" if label else number(value))
            verdicts.append(met)
        if all(v is None for v in verdicts):
            verdict = "not recorded"
        elif all(verdicts):
            verdict = "met"
        elif not any(verdicts):
            verdict = "**missed**"
        else:
            missed = [label for (label, _), v in zip(selectors, verdicts) if not v]
            verdict = "**missed** at " + ", ".join(missed)
        target = f"{sense} {threshold:g} {unit}".rstrip()
        measured = " / ".join(figures) + ("" if verdict == "not recorded" else f" {unit}")
        report = ", ".join(f"`{f}`" for f in dict.fromkeys(files))
        lines.append(f"| {what} | {target} | {measured} | {verdict} | {report} |")
    return lines


def peers_table(reports):
    lines = ["| case | covoxslam (GPU unless said) | peers, published |", "|---|---:|---|"]
    for what, selector, unit, peer in PEERS:
        value = lookup(reports, selector)
        shown = "not recorded" if value is None else f"{number(value)} {unit}"
        lines.append(f"| {what} | {shown} | {peer} |")
    return lines


def case_rows(reports, name, prefix, metric):
    report = reports.get(name)
    if report is None:
        return {}
    return {row["case"][len(prefix):]: row["value"] for row in report["results"]
            if row["case"].startswith(prefix) and row["metric"] == metric}


def tsdf_table(reports):
    gpu = case_rows(reports, "tsdf.json", "cuda ", TSDF_MS)
    cpu = case_rows(reports, "tsdf_cpu_2core.json", "cpu ", TSDF_MS)
    updates = case_rows(reports, "tsdf.json", "cuda ", "voxel updates per frame (mean)")
    rays = case_rows(reports, "tsdf.json", "cuda ", "rays cast per frame (mean)")
    lines = ["| case | GPU ms/frame | CPU twin ms/frame | rays per frame | voxel visits per frame |",
             "|---|---:|---:|---:|---:|"]
    for case in dict.fromkeys(list(gpu) + list(cpu)):
        lines.append(f"| {case} | {number(gpu.get(case))} | {number(cpu.get(case))} | "
                     f"{number(rays.get(case))} | {number(updates.get(case))} |")
    return lines


def hash_table_table(reports):
    lines = ["| load factor | GPU insert | GPU find | GPU erase | CPU twin insert | CPU twin find "
             "| CPU twin erase |", "|---:|---:|---:|---:|---:|---:|---:|"]
    for load in ("0.5", "0.7", "0.85"):
        cells = []
        for name, prefix in (("hash_table.json", "cuda"), ("hash_table_cpu_2core.json", "cpu")):
            for metric in ("insert (activate)", "find", "erase"):
                cells.append(number(lookup(reports, (name, f"{prefix} load {load}", metric))))
        lines.append(f"| {load} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append("Mkeys/s, 50 M keys.")
    return lines


def esdf_mesh_table(reports):
    lines = ["| case | ESDF GPU | ESDF CPU twin | mesh GPU | mesh CPU twin | block meshes to the "
             "host, GPU | changed blocks |", "|---|---:|---:|---:|---:|---:|---:|"]
    esdf_gpu = case_rows(reports, "esdf.json", "cuda ", INCREMENTAL)
    esdf_cpu = case_rows(reports, "esdf_cpu_2core.json", "cpu ", INCREMENTAL)
    mesh_gpu = case_rows(reports, "mesh.json", "cuda ", INCREMENTAL)
    mesh_cpu = case_rows(reports, "mesh_cpu_2core.json", "cpu ", INCREMENTAL)
    copy = case_rows(reports, "mesh.json", "cuda ", "block meshes to the host (median)")
    blocks = case_rows(reports, "esdf.json", "cuda ", "changed blocks per frame (median)")
    for case in dict.fromkeys(list(esdf_gpu) + list(esdf_cpu)):
        lines.append(f"| {case} | {number(esdf_gpu.get(case))} | {number(esdf_cpu.get(case))} | "
                     f"{number(mesh_gpu.get(case))} | {number(mesh_cpu.get(case))} | "
                     f"{number(copy.get(case))} | {number(blocks.get(case))} |")
    lines.append("")
    lines.append("Incremental updates, median ms per frame.")
    return lines


def backend_table(reports):
    lines = ["| graph | GPU, block-Jacobi | GPU, odometry chain | CPU twin, chain | Ceres "
             "SPARSE_SCHUR x4 | Ceres / best GPU | final cost GPU / Ceres / truth |",
             "|---|---:|---:|---:|---:|---:|---|"]
    graphs = [(f"{n} submaps, registration terms", case) for n, case in REGISTRATION_GRAPHS]
    graphs.append(("parking-garage, SE(3)", "parking-garage se3"))
    for label, case in graphs:
        jacobi = lookup(reports, ("backend.json", f"{case} cuda block-Jacobi", SOLVE))
        chain = lookup(reports, ("backend.json", f"{case} cuda odometry chain", SOLVE))
        cpu = lookup(reports, ("backend_cpu_2core.json", f"{case} cpu odometry chain", SOLVE))
        ceres = lookup(reports, ("backend_cpu_2core.json", f"{case} ceres SPARSE_SCHUR x4", SOLVE))
        gpu = [v for v in (jacobi, chain) if v is not None]
        ratio = "n/a"
        if ceres is not None and gpu:
            ratio = f"{ceres / min(gpu):.0f}x" if ceres >= 10 * min(gpu) else \
                f"{ceres / min(gpu):.2f}x"
        costs = [lookup(reports, ("backend.json", f"{case} cuda block-Jacobi", "final cost")),
                 lookup(reports, ("backend_cpu_2core.json", f"{case} ceres SPARSE_SCHUR x4",
                                  "final cost")),
                 lookup(reports, ("backend.json", f"{case} truth", "final cost"))]
        lines.append(f"| {label} | {number(jacobi)} | {number(chain)} | {number(cpu)} | "
                     f"{number(ceres)} | {ratio} | " + " / ".join(number(c) for c in costs) + " |")
    lines.append("")
    lines.append("Median solve time in ms. Ceres runs on the CPU host of the CPU twin's report, "
                 "so the ratio compares two machines.")
    return lines


def accuracy_table(reports):
    lines = ["| case | scans | submaps | odometry | covoxslam | max error | real-time factor |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    report = reports.get("accuracy.json")
    if report is None:
        return lines
    cases = list(dict.fromkeys(row["case"] for row in report["results"]))
    for case in cases:
        def get(metric):
            return lookup(reports, ("accuracy.json", case, metric))
        odometry = get("ATE RMSE odometry")
        ours = get("ATE RMSE covoxslam")
        if odometry is None:  # against another system's estimate, not ground truth
            odometry = get("distance to reference RMSE odometry")
            ours = get("distance to reference RMSE covoxslam")
            label = f"{case} (distance to a reference estimate)"
        else:
            label = case
        lines.append(f"| {label} | {number(get('scans'))} | {number(get('submaps'))} | "
                     f"{with_unit(odometry, ' m')} | {with_unit(ours, ' m')} | "
                     f"{with_unit(get('max error covoxslam'), ' m')} | "
                     f"{with_unit(get('real-time factor'), 'x')} |")
    return lines


def loops_table(reports):
    lines = ["| flight | odometry | covoxslam | closures | wrong | real-time factor | "
             "loose odometry sigmas | wrong | per-link noise estimate | wrong |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    report = reports.get(LOOPS)
    if report is None:
        return lines
    for case in dict.fromkeys(row["case"] for row in report["results"]):
        def get(name, metric):
            return lookup(reports, (name, case, metric))
        cells = [with_unit(get(LOOPS, "ATE RMSE covoxslam"), " m"),
                 number(get(LOOPS, "loop closures accepted")),
                 number(get(LOOPS, "loop closures wrong by > 1 m or 5 deg")),
                 with_unit(get(LOOPS, "real-time factor"), "x")]
        for name in (LOOPS_LOOSE, LOOPS_PER_LINK):
            cells += [with_unit(get(name, "ATE RMSE covoxslam"), " m"),
                      number(get(name, "loop closures wrong by > 1 m or 5 deg"))]
        label = case.replace("simulated loops ", "")
        lines.append(f"| {label} | {with_unit(get(LOOPS, 'ATE RMSE odometry'), ' m')} | "
                     + " | ".join(cells) + " |")
    return lines


def pipeline_table(reports):
    report = reports.get("pipeline.json")
    if report is None:
        return ["Not recorded: `tools/gpu_suite.sh build flight` writes `docs/benchmarks/"
                "pipeline.json`."]
    lines = ["| metric | value |", "|---|---:|"]
    # The run's own case; run_slam's timeline cases (t=NNNNs) follow it and have their own table.
    first = report["results"][0]["case"] if report["results"] else None
    for row in report["results"]:
        if row["case"] == first:
            lines.append(f"| {row['metric']} | {number(row['value'])} {row['unit']} |")
    return lines


TIMELINE_CASE = re.compile(r"^t=(\d+)s( end)?$")
MISSION_COLUMNS = [("host RSS", "host RSS MB"), ("device memory used", "GPU used MB"),
                   ("map memory", "map voxels MB (full size)"),
                   ("submaps", "submaps"), ("scan time p50", "scan p50 ms"),
                   ("scan time p95", "scan p95 ms"), ("scan time max", "scan max ms"),
                   ("registration per submap", "registration ms per submap"),
                   ("partners per submap", "partners per submap"),
                   ("restores per submap", "restores per submap"),
                   ("solve per submap", "solve ms per submap")]


def mission_table(reports, name="mission_cpu.json"):
    report = reports.get(name)
    if report is None:
        return [f"Not recorded: `run_slam --timeline-interval-s 30 --json "
                f"docs/benchmarks/{name}` writes it."]
    samples = {}
    for row in report["results"]:
        if TIMELINE_CASE.match(row["case"]):
            samples.setdefault(row["case"], {})[row["metric"]] = row["value"]
    # Columns the report has (the GPU's memory only where the run was on a GPU).
    columns = [c for c in MISSION_COLUMNS
               if any(c[0] in values for values in samples.values())]
    lines = ["| mission time | wall time | " + " | ".join(label for _, label in columns)
             + " |", "|---:|---:|" + "---:|" * len(columns)]
    for case, values in samples.items():
        shown = f"{int(TIMELINE_CASE.match(case).group(1))} s" + (
            " (after the final solve)" if case.endswith(" end") else "")
        cells = [number(values.get(metric)) for metric, _ in columns]
        lines.append(f"| {shown} | {with_unit(values.get('wall time'), ' s')} | "
                     + " | ".join(cells) + " |")
    first = report["results"][0]["case"] if report["results"] else None
    summary = {row["metric"]: row["value"] for row in report["results"] if row["case"] == first}
    lines.append("")
    lines.append(f"Whole run ({first}): real-time factor "
                 f"{with_unit(summary.get('real-time factor'), 'x')}, peak host memory "
                 f"{with_unit(summary.get('host peak RSS'), ' MB')}, ATE "
                 f"{with_unit(summary.get('ATE RMSE covoxslam'), ' m')} (odometry "
                 f"{with_unit(summary.get('ATE RMSE odometry'), ' m')}).")
    if "submaps resident" in summary:
        lines.append("")
        lines.append(f"Finished submaps at the end: {number(summary.get('submaps resident'))} "
                     f"resident ({with_unit(summary.get('resident submap memory'), ' MB')}"
                     + (f", peak {with_unit(summary.get('peak resident submap memory'), ' MB')}"
                        if "peak resident submap memory" in summary else "")
                     + "), "
                     f"{number(summary.get('submaps compact'))} compact "
                     f"({with_unit(summary.get('compact submap memory'), ' MB')}), "
                     f"{number(summary.get('submaps on disk'))} on disk; "
                     f"{number(summary.get('submap restores'))} restores in "
                     f"{with_unit(summary.get('submap restore time'), ' s')}"
                     + (f"; meshes {with_unit(summary.get('submap mesh memory'), ' MB')} in "
                        "host memory." if "submap mesh memory" in summary else "."))
    if "map file size" in summary:
        lines.append("")
        lines.append(f"Map file {with_unit(summary.get('map file size'), ' MB')}, saved in "
                     f"{with_unit(summary.get('map save time'), ' s')}.")
    return lines


def sources_table(reports):
    lines = ["| report | device | command |", "|---|---|---|"]
    for name, report in reports.items():
        command = shown_command(report["command"]).replace("|", "\\|")
        lines.append(f"| `{name}` | {report['device']} | `{command}` |")
    return lines


BLOCKS = {
    "goals": goals_table,
    "peers": peers_table,
    "tsdf": tsdf_table,
    "hash_table": hash_table_table,
    "esdf_mesh": esdf_mesh_table,
    "backend": backend_table,
    "accuracy": accuracy_table,
    "loops": loops_table,
    "pipeline": pipeline_table,
    "mission": mission_table,
    "mission_gpu": lambda reports: mission_table(reports, "mission_gpu_bag.json"),
    "sources": sources_table,
}

MARKER = re.compile(r"^<!-- generated: (\w+) -->\n(.*?)^<!-- end generated: \1 -->$",
                    re.MULTILINE | re.DOTALL)


def rewrite(text, reports):
    unknown = [m.group(1) for m in MARKER.finditer(text) if m.group(1) not in BLOCKS]
    if unknown:
        sys.exit("unknown generated block(s): " + ", ".join(unknown))

    def replace(match):
        name = match.group(1)
        body = "\n".join(BLOCKS[name](reports))
        return f"<!-- generated: {name} -->\n{body}\n<!-- end generated: {name} -->"

    return MARKER.sub(replace, text)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--doc", default=os.path.join(REPO, "docs", "performance.md"))
    parser.add_argument("--check", action="store_true",
                        help="exit 1 when a generated block is out of date; write nothing")
    args = parser.parse_args()
    with open(args.doc) as f:
        text = f.read()
    updated = rewrite(text, load_reports())
    if args.check:
        if updated != text:
            sys.exit(f"{args.doc}: generated tables are out of date; run {sys.argv[0]}")
        return
    if updated != text:
        with open(args.doc, "w") as f:
            f.write(updated)
        print(f"rewrote the generated tables of {args.doc}")


if __name__ == "__main__":
    main()
