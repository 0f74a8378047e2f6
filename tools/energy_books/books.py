#!/usr/bin/env python3
"""Energy books of finished runs, per output step and per step (docs/results.md, "Energy books (4.3 m/s)").

Usage:
    python3 tools/energy_books/books.py [--times 100,200,300,400,500,1000] [--window 50]
        [--plot PNG] [--csv-dir DIR] LABEL=RUN_DIR [LABEL=RUN_DIR ...]

Reads each run's history.csv (lines starting with '#' skipped, columns by name; docs/configuration.md,
"history.csv") and prints, per run:

1. The books at the given times (us): the external work W (N mm per mm of thickness) and, as fractions of
   W, the kinetic energy K, the stored energy Psi, the damage dissipation (trapezoidal rule), the erosion
   energy, the contact loss, the transfer loss, the integration remainder and the remainder
   R = W + E_0 - K - Psi - damage - erosion - contact = transfer + integration. The integration remainder
   is the part no column measures (the "unexplained" remainder). The recomputed remainder is checked
   against the energy_remainder column.
2. Per window of --window us: what the remainder, its transfer and integration parts, the damage and the
   erosion energy grew by, the crack's growth and the mean kinetic energy.
3. Where the remainder is made, step by step: the steps split into those that book erosion energy (the
   stored energy of points eroded in the step before; history.csv has no count of eroded points, the
   erosion energy booked in a step stands for it), those with damage but no erosion (damage increment
   above 1e-4 W) and the quiet rest; per class the steps' count and the remainder, transfer and
   integration parts made in them. Then the steps with a flag: a retried step (attempts > 1), a cut time
   step (dt below the run's largest), new PETSc objects (new_pattern, after step 1), several contact
   solves, crack growth, with the mean remainder per flagged and per unflagged step. Then the Pearson
   correlation of the per-step increments of the transfer and integration parts with the per-step
   erosion energy, damage, stored-energy change, crack speed and kinetic energy, and a least-squares fit
   dR = a dE + b dD + c per step.

--csv-dir writes DIR/LABEL-books.csv: every step's books (N mm/mm), their fractions of W and increments
and the flags. --plot writes a PNG of R/W, transfer/W and integration/W against time and of the remainder
made in erosion, damage and quiet steps. Standard library and matplotlib only. Energies of a 3D run are
per run, not per mm (its fractions are the same).
"""

import argparse
import csv
import math
import sys
from pathlib import Path

COLUMNS = {
    "W": "external_work",
    "K": "kinetic_energy",
    "Psi": "stored_energy",
    "damage": "damage_dissipation",
    "erosion": "erosion_energy",
    "contact": "contact_loss",
    "transfer": "transfer_loss",
    "remainder": "energy_remainder",
    "integration": "integration_remainder",
}
BOOKS = ["K", "Psi", "damage", "erosion", "contact", "transfer", "integration", "remainder"]
# The integration remainder's split (runs of 2026-12-08 on): the law's time rule, of it the eroded points'
# last half-stress, and the grid's Newmark balance (integration - law).
SPLIT = {"law": "law_remainder", "eroded": "eroded_stress_work"}


def read_history(run):
    with open(Path(run) / "history.csv", newline="") as f:
        lines = [line for line in f if not line.startswith("#")]
    rows = list(csv.DictReader(lines))
    if not rows:
        sys.exit(f"{run}: history.csv has no rows")
    missing = [c for c in list(COLUMNS.values()) + ["time", "dissipated_energy"] if c not in rows[0]]
    if missing:
        sys.exit(f"{run}: history.csv lacks {', '.join(missing)} (written before the energy books?)")
    return rows


def num(row, key, default=0.0):
    value = row.get(key)
    try:
        return float(value) if value not in (None, "") else default
    except ValueError:
        return default


def steps_of(rows):
    """Per step: the books (N mm/mm), their increments and the step's flags."""
    out, prev = [], None
    dt_max = max(num(r, "dt") for r in rows)
    for row in rows:
        s = {k: num(row, c) for k, c in COLUMNS.items()}
        s["split"] = all(c in row for c in SPLIT.values())
        s.update({k: num(row, c) for k, c in SPLIT.items()})
        s["grid"] = s["integration"] - s["law"]
        s["t"] = num(row, "time")
        s["step"] = int(num(row, "step"))
        # E_0, the kinetic energy at t = 0: dissipated_energy = W + E_0 - K - Psi.
        s["E0"] = num(row, "dissipated_energy") - s["W"] + s["K"] + s["Psi"]
        s["R_check"] = (s["W"] + s["E0"] - s["K"] - s["Psi"] - s["damage"] - s["erosion"]
                        - s["contact"])
        s["crack_length"] = num(row, "crack_length")
        s["crack_speed"] = num(row, "crack_speed")
        s["attempts"] = int(num(row, "attempts", 1))
        s["dt"] = num(row, "dt")
        s["dt_cut"] = s["dt"] < dt_max * (1 - 1e-9)
        s["new_pattern"] = int(num(row, "new_pattern")) == 1 and s["step"] > 1
        s["contact_solves"] = int(num(row, "contact_solves", 1))
        base = prev or {k: 0.0 for k in list(COLUMNS) + ["crack_length"]}
        for k in list(COLUMNS) + ["crack_length"]:
            s["d_" + k] = s[k] - base[k]
        out.append(s)
        prev = s
    return out


def at_time(steps, t_us):
    """The step at t_us (within half a step), else None."""
    best = min(steps, key=lambda s: abs(s["t"] * 1e6 - t_us))
    return best if abs(best["t"] * 1e6 - t_us) <= 0.5 * max(best["dt"] * 1e6, 1e-9) + 1e-6 else None


def classify(steps):
    w_end = max(s["W"] for s in steps)
    for s in steps:
        if s["d_erosion"] > 0:
            s["class"] = "erosion"
        elif s["d_damage"] > 1e-4 * w_end:
            s["class"] = "damage"
        else:
            s["class"] = "quiet"


def pearson(a, b):
    n = len(a)
    if n < 3:
        return float("nan")
    ma, mb = sum(a) / n, sum(b) / n
    sa = math.sqrt(sum((x - ma) ** 2 for x in a))
    sb = math.sqrt(sum((y - mb) ** 2 for y in b))
    if sa == 0 or sb == 0:
        return float("nan")
    return sum((x - ma) * (y - mb) for x, y in zip(a, b)) / (sa * sb)


def lstsq(xs, y):
    """Least squares y ~ sum_j c_j x_j by the normal equations (a few columns); c and R^2."""
    m = len(xs)
    a = [[sum(xi * xj for xi, xj in zip(xs[i], xs[j])) for j in range(m)] for i in range(m)]
    b = [sum(xi * yi for xi, yi in zip(xs[i], y)) for i in range(m)]
    for i in range(m):  # Gauss-Jordan with partial pivoting
        p = max(range(i, m), key=lambda r: abs(a[r][i]))
        a[i], a[p], b[i], b[p] = a[p], a[i], b[p], b[i]
        if abs(a[i][i]) < 1e-300:
            return [float("nan")] * m, float("nan")
        for r in range(m):
            if r != i:
                f = a[r][i] / a[i][i]
                a[r] = [x - f * z for x, z in zip(a[r], a[i])]
                b[r] -= f * b[i]
    c = [b[i] / a[i][i] for i in range(m)]
    pred = [sum(c[j] * xs[j][k] for j in range(m)) for k in range(len(y))]
    my = sum(y) / len(y)
    ss = sum((yi - my) ** 2 for yi in y)
    r2 = 1 - sum((yi - pi) ** 2 for yi, pi in zip(y, pred)) / ss if ss > 0 else float("nan")
    return c, r2


def report(label, run, steps, times, window):
    last = steps[-1]
    print(f"== {label} ({run}): {len(steps)} steps to {last['t'] * 1e6:.0f} us, E_0 = {last['E0']:.3g}")
    worst = max(abs(s["R_check"] - s["remainder"]) for s in steps)
    print(f"   recomputed remainder against energy_remainder: largest difference {worst:.2e} N mm/mm")
    print("   books, % of W (W in N mm/mm):")
    print("   t (us) |       W |     K |   Psi | damage | erosion | contact | transfer | integration "
          "| remainder")
    for t_us in times:
        s = at_time(steps, t_us)
        if s is None or s["W"] <= 0:
            continue
        f = {k: 100 * s[k] / s["W"] for k in BOOKS + list(SPLIT) + ["grid"]}
        split = (f" | law {f['law']:.2f} (eroded {f['eroded']:.2f}), grid {f['grid']:.2f}"
                 if s["split"] else "")
        print(f"   {t_us:6.0f} | {s['W']:7.2f} | {f['K']:5.1f} | {f['Psi']:5.2f} | {f['damage']:6.2f} | "
              f"{f['erosion']:7.2f} | {f['contact']:7.3f} | {f['transfer']:8.2f} | "
              f"{f['integration']:11.2f} | {f['remainder']:9.2f}{split}")
    print(f"   per {window:.0f} us window (N mm/mm): growth of R, transfer, integration, damage, erosion, "
          "crack length (mm), mean K")
    t0 = 0.0
    while t0 < last["t"] * 1e6 - 1e-6:
        sel = [s for s in steps if t0 < s["t"] * 1e6 <= t0 + window + 1e-6]
        if sel:
            g = {k: sum(s["d_" + k] for s in sel) for k in ["remainder", "transfer", "integration",
                                                             "damage", "erosion", "crack_length"]}
            mk = sum(s["K"] for s in sel) / len(sel)
            print(f"   {t0:5.0f}-{t0 + window:5.0f}: R {g['remainder']:+7.3f}  T {g['transfer']:+7.3f}  "
                  f"I {g['integration']:+7.3f}  D {g['damage']:+7.3f}  E {g['erosion']:+7.3f}  "
                  f"crack {g['crack_length']:+6.1f}  K {mk:7.2f}")
        t0 += window
    classify(steps)
    total = {k: sum(s["d_" + k] for s in steps) for k in ["remainder", "transfer", "integration"]}
    print("   where the remainder is made (N mm/mm; share of the final value):")
    for cls in ["erosion", "damage", "quiet"]:
        sel = [s for s in steps if s["class"] == cls]
        g = {k: sum(s["d_" + k] for s in sel) for k in total}
        share = {k: (100 * g[k] / total[k] if total[k] else float("nan")) for k in total}
        print(f"   {cls:8s} steps {len(sel):5d}: R {g['remainder']:7.3f} ({share['remainder']:5.1f} %)  "
              f"T {g['transfer']:7.3f} ({share['transfer']:5.1f} %)  "
              f"I {g['integration']:7.3f} ({share['integration']:5.1f} %)")
    flags = {
        "attempts > 1": lambda s: s["attempts"] > 1,
        "dt cut": lambda s: s["dt_cut"],
        "new_pattern": lambda s: s["new_pattern"],
        "contact_solves > 1": lambda s: s["contact_solves"] > 1,
        "crack grows": lambda s: s["d_crack_length"] > 0,
    }
    print("   flagged steps: count, mean dR per flagged / unflagged step (N mm/mm)")
    for name, flag in flags.items():
        on = [s["d_remainder"] for s in steps if flag(s)]
        off = [s["d_remainder"] for s in steps if not flag(s)]
        mean = lambda v: sum(v) / len(v) if v else float("nan")  # noqa: E731
        print(f"   {name:19s} {len(on):5d}: {mean(on):+.4f} / {mean(off):+.4f}")
    late = [s for s in steps if s["t"] > 20e-6]  # after the plates' rise time and first wave
    d_psi = [s["d_Psi"] for s in late]
    rows = {
        "erosion energy": [s["d_erosion"] for s in late],
        "damage": [s["d_damage"] for s in late],
        "stored-energy change": d_psi,
        "crack speed": [s["crack_speed"] for s in late],
        "kinetic energy": [s["K"] for s in late],
    }
    d_t = [s["d_transfer"] for s in late]
    d_i = [s["d_integration"] for s in late]
    print("   correlation with the per-step transfer / integration increments (steps after 20 us):")
    for name, v in rows.items():
        print(f"   {name:21s} {pearson(d_t, v):+.2f} / {pearson(d_i, v):+.2f}")
    ones = [1.0] * len(late)
    for name, key in [("R", "remainder"), ("transfer", "transfer"), ("integration", "integration")]:
        c, r2 = lstsq([rows["erosion energy"], rows["damage"], ones], [s["d_" + key] for s in late])
        print(f"   fit d{name} = {c[0]:.3f} dE + {c[1]:.3f} dD + {c[2]:.4f} per step (R^2 {r2:.2f})")
    print()


def write_csv(path, steps):
    keys = ["W"] + BOOKS
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "time_s", "dt_s"] + keys + [k + "_of_W" for k in BOOKS]
                   + ["d_" + k for k in keys] + ["class", "attempts", "dt_cut", "new_pattern",
                                                  "contact_solves", "crack_length", "crack_speed"])
        for s in steps:
            frac = [s[k] / s["W"] if s["W"] > 0 else 0.0 for k in BOOKS]
            w.writerow([s["step"], f"{s['t']:.9e}", f"{s['dt']:.6e}"]
                       + [f"{s[k]:.9e}" for k in keys] + [f"{x:.6e}" for x in frac]
                       + [f"{s['d_' + k]:.6e}" for k in keys]
                       + [s["class"], s["attempts"], int(s["dt_cut"]), int(s["new_pattern"]),
                          s["contact_solves"], s["crack_length"], s["crack_speed"]])


def plot(path, runs):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (label, steps) in enumerate(runs):
        c = colours[k % len(colours)]
        # From 5 % of the final work on (the first steps' fractions of a tiny W are noise).
        w_end = steps[-1]["W"]
        first = next(i for i, s in enumerate(steps) if s["W"] >= 0.05 * w_end)
        t = [s["t"] * 1e6 for s in steps[first:]]
        frac = lambda key: [100 * s[key] / s["W"] for s in steps[first:]]  # noqa: E731
        axes[0].plot(t, frac("remainder"), color=c, label=label)
        axes[1].plot(t, frac("integration"), color=c, label=f"{label}: integration")
        axes[1].plot(t, frac("transfer"), color=c, ls="--", label=f"{label}: transfer")
        for cls, ls in [("erosion", "-"), ("damage", "--"), ("quiet", ":")]:
            acc, ys = 0.0, []
            for i, s in enumerate(steps):
                if s["class"] == cls:
                    acc += s["d_remainder"]
                if i >= first:
                    ys.append(100 * acc / s["W"])
            axes[2].plot(t, ys, color=c, ls=ls, label=f"{label}: {cls} steps")
    axes[0].axhline(3.0, color="k", lw=0.8, ls=":")
    axes[0].set_title("remainder R = W + E_0 - K - Psi - damage - erosion - contact", fontsize=9)
    axes[1].set_title("its parts: integration (solid), transfer (dashed)", fontsize=9)
    axes[2].set_title("R made in steps with erosion (solid), damage (dashed), quiet (dotted)", fontsize=9)
    for ax in axes:
        ax.set_xlabel("time (us)")
        ax.set_ylabel("% of the external work W")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[1].legend(fontsize=6, ncol=2)
    axes[2].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="LABEL=RUN_DIR (or RUN_DIR)")
    ap.add_argument("--times", default="100,200,300,400,500,1000", help="output times in us")
    ap.add_argument("--window", type=float, default=50.0, help="window of the growth table in us")
    ap.add_argument("--plot", help="PNG to write")
    ap.add_argument("--csv-dir", help="directory for LABEL-books.csv per run")
    args = ap.parse_args()
    times = [float(x) for x in args.times.split(",") if x]
    runs = []
    for spec in args.runs:
        label, _, run = spec.partition("=") if "=" in spec else (Path(spec).name, "", spec)
        steps = steps_of(read_history(run))
        report(label, run, steps, times, args.window)
        if args.csv_dir:
            Path(args.csv_dir).mkdir(parents=True, exist_ok=True)
            write_csv(Path(args.csv_dir) / f"{label}-books.csv", steps)
        runs.append((label, steps))
    if args.plot:
        plot(args.plot, runs)


if __name__ == "__main__":
    main()
