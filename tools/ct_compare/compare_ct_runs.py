#!/usr/bin/env python3
"""Side-by-side summary of finished CT runs (docs/results.md).

Usage:
    python3 tools/ct_compare/compare_ct_runs.py OUT_PREFIX LABEL=RUN_DIR [LABEL=RUN_DIR ...]

Reads each run's history.csv and crack.json and writes
    OUT_PREFIX-force.png       opening force of the loading plate against time (N per mm of thickness)
    OUT_PREFIX-width.png       median widths of the d >= 0.9 bands and of the d >= 0.5 zone against time (mm)
    OUT_PREFIX-table.md        a Markdown table of the final crack metrics, energies and wall time, and
                               each run's largest distance from the first run's crack path at equal crack
                               length (the crack tips of history.csv, step by step)
Units: mm, s, N, MPa, t; forces and energies per mm of thickness (a 3D run's, whose config.toml has an
[extrusion] table, are divided by its thickness).
"""

import csv
import json
import sys
import tomllib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_history(run: Path):
    with open(run / "history.csv", newline="") as f:
        lines = [line for line in f if not line.startswith("#")]
    rows = list(csv.DictReader(lines))
    return rows


def thickness(run: Path):
    """The plate thickness (mm) of a 3D run, 1 for a plane one (its values are per mm already)."""
    config = tomllib.loads((run / "config.toml").read_text())
    return float(config.get("extrusion", {}).get("thickness", 1.0))


def col(rows, name):
    return [float(r[name]) for r in rows if r.get(name) not in (None, "")]


def tip_at_length(rows, length):
    """The crack tip (mm) at the first step whose crack length reaches `length` (mm), None if none does."""
    for r in rows:
        if r.get("crack_length") not in (None, "") and float(r["crack_length"]) >= length:
            return float(r["crack_tip_x"]), float(r["crack_tip_y"])
    return None


def path_gap(rows, reference):
    """The largest distance (mm) between the crack tips of `rows` and `reference` at equal crack length,
    over lengths from 5 mm to the shorter final length in 1 mm steps (nan without a common length)."""
    final = min(max(col(rows, "crack_length"), default=0.0), max(col(reference, "crack_length"), default=0.0))
    gaps = []
    length = 5.0
    while length <= final:
        a, b = tip_at_length(rows, length), tip_at_length(reference, length)
        if a and b:
            gaps.append(((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2) ** 0.5)
        length += 1.0
    return max(gaps) if gaps else float("nan")


def main(argv):
    if len(argv) < 3:
        print(__doc__)
        return 2
    prefix = Path(argv[1])
    runs = []
    for arg in argv[2:]:
        label, _, path = arg.partition("=")
        run = Path(path)
        rows = read_history(run)
        per_mm = thickness(run)
        if per_mm != 1.0:
            for r in rows:
                for name in ("loading_plate_fy", "dissipated_energy"):
                    if r.get(name) not in (None, ""):
                        r[name] = str(float(r[name]) / per_mm)
        crack = json.loads((run / "crack.json").read_text())
        for state in crack["states"]:
            state["dissipated"] = [d / per_mm for d in state.get("dissipated", [float("nan")] * 2)]
        runs.append((label, run, rows, crack))

    fig, ax = plt.subplots(figsize=(7, 4))
    for label, _, rows, _ in runs:
        t = [1e6 * v for v in col(rows, "time")]
        ax.plot(t, [-v for v in col(rows, "loading_plate_fy")], label=label)
    ax.set_xlabel("time [us]")
    ax.set_ylabel("opening force of the loading plate [N/mm]")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(f"{prefix}-force.png", dpi=110)

    fig, ax = plt.subplots(figsize=(7, 4))
    for label, _, _, crack in runs:
        st = [s for s in crack["states"] if s.get("band_width", 0) > 0]
        line = ax.plot([1e6 * s["time"] for s in st], [s["band_width"] for s in st], "o-", label=f"{label}, d >= 0.9")
        ax.plot(
            [1e6 * s["time"] for s in st],
            [s.get("zone_width", float("nan")) for s in st],
            "s--",
            color=line[0].get_color(),
            label=f"{label}, d >= 0.5",
        )
    ax.set_xlabel("time [us]")
    ax.set_ylabel("median width across the bands [mm]")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(f"{prefix}-width.png", dpi=110)

    out = [
        "| run | classification | bands (deg) | length (mm) | band width median / max (mm) | "
        "zone width d >= 0.5 (mm) | path gap to the first run (mm) | "
        "peak opening force (N/mm) | peak support reaction (N/mm) | min opening force after the peak (N/mm) | "
        "dissipated tension / compression (N mm/mm) | nonlocal-only points | steps | wall (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, run, rows, crack in runs:
        last = crack["states"][-1]
        force = [-v for v in col(rows, "loading_plate_fy")]
        k = max(range(len(force)), key=lambda i: force[i])
        after = min(force[k:]) if force else float("nan")
        diss = last.get("dissipated", [float("nan")] * 2)
        wall = sum(col(rows, "wall_total"))
        support = max((abs(v) for v in col(rows, "support_plate_fy")), default=float("nan"))
        gap = path_gap(rows, runs[0][2])
        bands = ", ".join(f"{b['angle_degrees']:.0f}" for b in last["bands"])
        out.append(
            f"| {label} | {last['classification']} | {bands} | {last['length']:.1f} | "
            f"{last.get('band_width', float('nan')):.1f} / {last.get('band_width_max', float('nan')):.1f} | "
            f"{last.get('zone_width', float('nan')):.1f} | {gap:.1f} | "
            f"{force[k]:.0f} at {1e6 * float(rows[k]['time']):.0f} us | {support:.0f} | {after:.0f} | "
            f"{diss[0]:.1f} / {diss[1]:.1f} | {last.get('nonlocal_points', 0)} | {len(rows)} | {wall:.0f} |"
        )
    Path(f"{prefix}-table.md").write_text("\n".join(out) + "\n")
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
