#!/usr/bin/env python3
"""Scaling model of one implicit step of the CT test on P processes (docs/scaling.md).

Every input is a count or a time measured in this repository (docs/benchmarks.md; the section is named
next to each number) or an assumption named in ASSUMED. The model is

    T(P) = T_points(P) + T_solve(P) + T_grid(P) + T_comm(P)        (s per step)

for three versions of the code: "today" (bands of cell rows, whole-grid arrays on every process, the
gather of all unknowns after each solve, exchanges with all-to-all counts), "dist" (issue 46 item 2: each
process holds its own and ghost nodes only; bands as today) and "boxes" (dist with a 2D/3D process grid
instead of bands: not part of item 2, shown because bands stop at one cell row per process).

    python3 tools/scaling_model/model.py                 # tables to stdout
    python3 tools/scaling_model/model.py --write-doc     # also rewrites the tables in docs/scaling.md
    python3 tools/scaling_model/model.py --plot          # docs/img/scaling_model.png (matplotlib)
    python3 tools/scaling_model/model.py --measured runs/scaling/scaling.csv   # model against a series

Units: s, B, mm. Standard library only (matplotlib for --plot).
"""

import argparse
import csv
import math
import os
import re
import sys
from collections import defaultdict

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
PS = [1, 2, 4, 8, 16, 32, 64, 128, 256, 512]

# ---------------------------------------------------------------------------------------------------
# Assumptions (not measured here): the cluster and a few code constants not timed on their own.
# ---------------------------------------------------------------------------------------------------
ASSUMED = dict(
    alpha=1.5e-6,  # s, latency of one message (inter-node; used for on-node messages too)
    node_bw=10e9,  # B/s, network bandwidth of one node (shared by its processes)
    shm_bw=5e9,  # B/s, one process copying to another on the same node
    ppn=32,  # processes (cores) per node, one process per core, 1 thread each
    node_mem_bw=100e9,  # B/s, memory bandwidth of one node (all cores streaming)
    t_node_2d=0.2e-6,  # s per grid node and step of whole-grid loops (estimate, docs/scaling.md)
    t_node_3d=0.3e-6,
    ghost_cost=1.0,  # a ghost point costs its process as much as an own point
    thread_eff=1.0,  # two rayon threads do the point loops twice as fast as one
    fact_over_it=5.0,  # 2D: one ILU(0) factorisation costs five GMRES iterations (benchmarks.md)
    k_growth_3d=0.10,  # 3D (ASM overlap 1): Krylov growth per doubling of P (not measured)
    solves_per_step=1.12,  # SNES solves per step (contact re-solves: 126 of 1000 steps re-solve)
    reductions_per_step=14,  # the program's own reductions outside evaluations and solves (code count)
    gmres_reductions=2,  # allreduces per GMRES iteration (VecMDot + VecNorm)
    newton_reductions=4,  # allreduces per Newton iteration (norms, line search)
)

# Single-core memory streaming rate of PETSc's kernels: MatMult at 1.05 GFlop/s (docs/benchmarks.md,
# "Geometric multigrid", 2026-12-06, Intel Xeon), 2 flops and 12 B (value + column index) per nonzero.
CORE_STREAM = 1.05e9 / 2 * 12

# ---------------------------------------------------------------------------------------------------
# Measured inputs (docs/benchmarks.md)
# ---------------------------------------------------------------------------------------------------
# "Processes: points owned by processes" (2026-12-02, 2-core AMD EPYC, build cda783c), paper-size CT
# at 4.3 m/s (configs/ct-paper-c1-4.3mps.toml), per step: set-up, assembly, PETSc, step (s), Newton
# and Krylov iterations per step; 1 process x 2 threads and 2 processes x 1 thread.
MEASURED_2D = {
    "elastic": {
        "steps": "2-16",
        1: dict(setup=0.159, assembly=0.305, petsc=0.229, step=0.727, newton=2.07, krylov=9.5),
        2: dict(setup=0.141, assembly=0.288, petsc=0.220, step=0.679, newton=2.13, krylov=10.2),
    },
    "cracked": {
        "steps": "152-166",
        1: dict(setup=0.255, assembly=0.851, petsc=1.500, step=2.650, newton=5.40, krylov=30.1),
        2: dict(setup=0.210, assembly=0.939, petsc=1.071, step=2.265, newton=5.40, krylov=37.8),
    },
}
# "Three dimensions: cost per point" (2026-12-02, AMD EPYC, criterion, 2 threads): 2D microplane,
# 20,000 points: evaluate 7.10 ms, residual 5.00 ms (-> core-us per point: x 2 threads / 20,000).
C_RES_2D = 5.00e-3 * 2 / 20000
C_EVAL_2D = 7.10e-3 * 2 / 20000
# "The 3D CT demo" (2026-12-02, 2 processes x 1 thread, 39,120 points, 250 steps): set-up 0.26,
# assembly 0.78, PETSc 1.51 s per step; 3.03 Newton and 18.2 Krylov per step; 3,449 ghosts per step;
# about 36,000 unknowns on average (30,888 at the start, about 42,000 cracked).
DEMO_3D = dict(points=39120, setup=0.26, assembly=0.78, petsc=1.51, newton=3.03, krylov=18.2,
               ghosts=3449, unknowns=36000)
# The same section, first 50 steps: PETSc 58.4 s factored at every Newton iteration against 36.8 s
# factored every second one, at the same Krylov count: a factorisation costs (58.4-36.8)/(3.03-1.6)/50 s.
DEMO_3D_LAG = dict(petsc_lag1=58.4, petsc_lag2=36.8, steps=50)
# ILU(0)'s Krylov iterations per Newton iteration against the cell size (2D CT, r = 0.25 (h/1 mm)^2):
# "Geometric multigrid" (2026-12-06): 3.6 (2 mm), 4.7 (1 mm), 8.3 (0.5 mm); the CT demo (4 mm) 3.4
# ("The benchmark command", 2026-12-01).
K_OF_H = [(4.0, 3.4), (2.0, 3.6), (1.0, 4.7), (0.5, 8.3)]
# Ghost copies per step on 2 processes at the paper's size: 1,980 ("On a cluster", 2026-12-02).
GHOSTS_P2 = 1980
# Bytes sent per process and step ("Bytes sent per process and step", 2026-12-03): kB per process and
# (of them) the unknowns' gathers. The paper-size rows are the build that still summed the whole physical
# residual over the processes; the demo rows the current exchanges.
BYTES_PAPER = {2: [(4169, 50), (3753, 37)], 3: [(5576, 122), (6989, 222), (4756, 92)],
               4: [(5737, 109), (5978, 137), (6355, 147), (4922, 82)]}
NEWTON_PAPER_3 = {2: 7, 3: 8, 4: 7}  # Newton iterations in the 3 steps
BYTES_DEMO = {2: [(443, 28), (267, 18)], 3: [(516, 31), (841, 59), (362, 24)],
              4: [(530, 31), (780, 59), (745, 52), (377, 24)]}
NEWTON_DEMO_10 = {2: 23, 3: 27, 4: 27}


def k_of_h(h):
    """ILU(0) Krylov iterations per Newton iteration at cell size h (mm), log-log interpolation of
    K_OF_H, extrapolated with the slope of the nearest segment."""
    pts = sorted(K_OF_H)
    if h <= pts[0][0]:
        (h0, k0), (h1, k1) = pts[0], pts[1]
    elif h >= pts[-1][0]:
        (h0, k0), (h1, k1) = pts[-2], pts[-1]
    else:
        for (h0, k0), (h1, k1) in zip(pts, pts[1:]):
            if h0 <= h <= h1:
                break
    s = math.log(k1 / k0) / math.log(h1 / h0)
    return k0 * (h / h0) ** s


# ---------------------------------------------------------------------------------------------------
# Geometry of the CT (docs/configuration.md, [ct]; configs/ct-paper-c1-4.3mps.toml)
# ---------------------------------------------------------------------------------------------------
class Case:
    """A CT specimen on a grid: points per cell row, active nodes per node row, grid sizes."""

    def __init__(self, name, dim, h, thickness=None, margin=8, notch_len=110.0, notch_w=10.0,
                 width=200.0, ppc=2, record_doubles=None):
        self.name, self.dim, self.h = name, dim, h
        nx = round(width / h)
        self.body_rows = round(width / h)
        lo = (width - notch_w) / 2
        notch_rows = [j for j in range(self.body_rows) if lo <= (j + 0.5) * h < lo + notch_w]
        layers = 1 if dim == 2 else ppc * round(thickness / h)  # point layers through the plate
        self.cells_z = 0 if dim == 2 else round(thickness / h)
        full = nx * ppc * ppc * layers
        notch = round((width - notch_len) / h) * ppc * ppc * layers
        self.rows = [notch if j in notch_rows else full for j in range(self.body_rows)]
        self.N = sum(self.rows)
        self.margin = margin
        self.ny = self.body_rows + 2 * margin  # cell rows of the grid (bands: at most one process each)
        zn = 1 if dim == 2 else self.cells_z + 4 + 1  # node layers (extrusion: 2 empty cells per face)
        self.row_nodes = (nx + 2 * margin + 1) * zn
        self.grid_nodes = self.row_nodes * (self.ny + 1)
        zact = 1 if dim == 2 else self.cells_z + 1
        act_full, act_notch = (nx + 1) * zact, (round((width - notch_len) / h) + 1) * zact
        self.active_rows = [act_notch if j in notch_rows[1:] else act_full
                            for j in range(self.body_rows + 1)]
        self.nf = dim + 1
        self.n = sum(self.active_rows) * self.nf  # unknowns
        self.record = 8 * (record_doubles or (66 if dim == 2 else 100))  # B per point record
        self.extent = (nx, self.body_rows, self.cells_z)  # cells of the body along x, y, z


def bands(case, P):
    """Cuts of P bands of about equal point counts (partition.rs, from_counts), in body cell rows."""
    total = sum(case.rows)
    cuts, cum, j = [0], 0.0, 0
    for r in range(1, P):
        target = total * r / P
        while j < len(case.rows) and cum + case.rows[j] <= target:
            cum += case.rows[j]
            j += 1
        cuts.append(max(j, cuts[-1] + 1))
    cuts.append(len(case.rows))
    return cuts


# A point in cell row j is sent to every other process whose node rows meet j-2 .. j+3 (REACH_ROWS = 3,
# partition.rs): the 3 cell rows below a cut go up, the 2 above go down. Measured 1,980 copies on 2
# processes against the 1,800 this rule gives at the seeded positions: deformed domains reach one row
# further for some points, a factor 1.1 (calibrated).
GHOST_BELOW, GHOST_ABOVE = 3, 2


def ghost_factor():
    c = Case("paper", 2, 1.0)
    cuts = bands(c, 2)
    k = cuts[1]
    rule = sum(c.rows[k - GHOST_BELOW:k]) + sum(c.rows[k:k + GHOST_ABOVE])
    return GHOSTS_P2 / rule


GF = None


def band_traffic(case, P):
    """Per process r of P bands: own points, ghosts received and sent, own active nodes."""
    global GF
    if GF is None:
        GF = ghost_factor()
    cuts = bands(case, P)
    out = []
    for r in range(P):
        a, b = cuts[r], cuts[r + 1]
        own = sum(case.rows[a:b])
        recv = sent = 0.0
        if r > 0:
            recv += sum(case.rows[max(0, a - GHOST_BELOW):a])
            sent += sum(case.rows[a:min(b, a + GHOST_ABOVE)])
        if r < P - 1:
            recv += sum(case.rows[b:b + GHOST_ABOVE])
            sent += sum(case.rows[max(a, b - GHOST_BELOW):b])
        nodes = sum(case.active_rows[a:b + (1 if r == P - 1 else 0)])
        out.append(dict(own=own, recv=recv * GF, sent=sent * GF, nodes=nodes,
                        neighbours=(r > 0) + (r < P - 1),
                        row_active=case.active_rows[min(b, len(case.active_rows) - 1)]))
    return out


def process_grid(case, P):
    """A process grid of P boxes over the body's cells with the smallest ghost volume."""
    ex, ey, ez = case.extent
    best = None
    for px in range(1, P + 1):
        if P % px:
            continue
        for py in range(1, P // px + 1):
            if (P // px) % py:
                continue
            pz = P // px // py
            if case.dim == 2 and pz != 1:
                continue
            bx, by = ex / px, ey / py
            bz = ez / pz if case.dim == 3 else 1.0
            if min(bx, by) < 1 or (case.dim == 3 and bz < 1):
                continue
            g = GHOST_BELOW + GHOST_ABOVE  # ghost cells across each cut axis (both sides together)
            vol = ((bx + g * (px > 1)) * (by + g * (py > 1))
                   * ((bz + g * (pz > 1)) if case.dim == 3 else 1.0))
            ratio = vol / (bx * by * bz) - 1.0
            if best is None or ratio < best[0]:
                best = (ratio, (px, py, pz), (bx, by, bz))
    return best


# ---------------------------------------------------------------------------------------------------
# Calibration: serial (1 process, 1 thread) costs of a step
# ---------------------------------------------------------------------------------------------------
def calibrate_2d(state, case):
    """Per-point and per-unknown costs of the 2D CT in `state` ("elastic" or "cracked") on one core."""
    m1 = MEASURED_2D[state][1]
    other = m1["step"] - m1["setup"] - m1["assembly"] - m1["petsc"]  # G2P, commit, energies
    te = ASSUMED["thread_eff"]
    w_pts = 2 * te * (m1["setup"] + m1["assembly"] + other)  # core-s: the point loops on one core
    e = MEASURED_2D["elastic"][1]
    scale = w_pts / (2 * te * (e["step"] - e["petsc"]))  # cracked over elastic point work
    c_res, c_eval = C_RES_2D * scale, C_EVAL_2D * scale  # the cracked points cost more
    s = ASSUMED["solves_per_step"]
    r_fin1 = (s + 1) * c_res * case.N / 2  # one process: cached evaluation, residual passes, 2 threads
    solve1 = m1["petsc"] - r_fin1  # PETSc's own work, one core
    k, K1 = m1["newton"], m1["krylov"] / m1["newton"]
    f = ASSUMED["fact_over_it"]
    t_it = solve1 / (k * (f + K1))
    K2 = MEASURED_2D[state][2]["krylov"] / MEASURED_2D[state][2]["newton"]
    return dict(t_pt=w_pts / case.N, c_res=c_res, c_eval=c_eval, k=k, K1=K1,
                t_it_u=t_it / case.n, t_f_u=f * t_it / case.n, fact_per_newton=1.0,
                a=K2 / K1 - 1.0, mem_bound=1.0)


def calibrate_3d(case):
    """Per-point and per-unknown costs of the 3D CT at cell size case.h on one core, from the 3D demo
    (4 mm cells, 2 processes)."""
    d = DEMO_3D
    # two cores' point work over the points they evaluated (own and ghosts)
    t_pt = (d["setup"] + d["assembly"]) * 2 / (d["points"] + d["ghosts"])
    lag = DEMO_3D_LAG
    fact_per_step = 1.6  # lag 2: factorisations at Newton iterations 0 and 2 of about 3 per step
    t_f = (lag["petsc_lag1"] - lag["petsc_lag2"]) / (d["newton"] - fact_per_step) / lag["steps"] * 2
    t_it = (d["petsc"] * 2 - fact_per_step * t_f) / d["krylov"]
    K_demo = d["krylov"] / d["newton"]
    K1 = K_demo * k_of_h(case.h) / k_of_h(4.0)
    return dict(t_pt=t_pt, c_res=0.0, c_eval=0.0, k=d["newton"], K1=K1,
                t_it_u=t_it / d["unknowns"], t_f_u=t_f / d["unknowns"],
                fact_per_newton=fact_per_step / d["newton"], a=ASSUMED["k_growth_3d"], mem_bound=1.0)


# ---------------------------------------------------------------------------------------------------
# The model
# ---------------------------------------------------------------------------------------------------
def log2c(P):
    return math.ceil(math.log2(P)) if P > 1 else 0


def bw_neighbour(P):
    """B/s of a neighbour exchange: on one node shared memory, else at most 2 processes of a node
    talk off-node at once (bands: consecutive ranks on a node)."""
    if P <= ASSUMED["ppn"]:
        return ASSUMED["shm_bw"]
    return min(ASSUMED["shm_bw"], ASSUMED["node_bw"] / 2)


def bw_collective(P):
    """B/s per process of an all-to-all pattern (gather of all unknowns, flags): the node's network
    link shared by its processes once P spans nodes."""
    if P <= ASSUMED["ppn"]:
        return ASSUMED["shm_bw"]
    return min(ASSUMED["shm_bw"], ASSUMED["node_bw"] / ASSUMED["ppn"])


def mem_contention(P):
    """Slow-down of memory-bound kernels (ILU, SpMV) when min(P, ppn) cores of a node stream at once."""
    busy = min(P, ASSUMED["ppn"])
    return max(1.0, busy * CORE_STREAM / ASSUMED["node_mem_bw"])


def step_time(case, cal, P, variant, detail=False, k_growth=None):
    """Seconds per step on P processes (1 thread each) and the terms, for the slowest process."""
    alpha = ASSUMED["alpha"]
    a = cal["a"] if k_growth is None else k_growth
    s = ASSUMED["solves_per_step"]
    k = cal["k"]
    if P > 1 and variant in ("today", "dist") and P > case.ny:
        return None  # bands: one cell row per process at least (partition.rs refuses more)
    # --- points: own points, ghosts, the physical residual after each solve
    if variant == "boxes" and P > 1:
        pg = process_grid(case, P)
        if pg is None:
            return None
        gratio = pg[0] * GF
        own = case.N / P
        ghosts = own * gratio
        (px, py, pz), (bx, by, bz) = pg[1], pg[2]
        halo_nodes = 2 * ((by + 1) * (bz + 1 if case.dim == 3 else 1) * (px > 1)
                          + (bx + 1) * (bz + 1 if case.dim == 3 else 1) * (py > 1)
                          + ((bx + 1) * (by + 1) if case.dim == 3 and pz > 1 else 0))
        neighbours = 2 * ((px > 1) + (py > 1) + (pz > 1)) + (4 if case.dim == 2 and px > 1 and py > 1 else 0)
        own_nodes = case.n / case.nf / P
        ghost_sent = ghosts
    elif P > 1:
        t = band_traffic(case, P)
        worst = max(t, key=lambda x: x["own"] + x["recv"])
        own, ghosts = worst["own"], worst["recv"]
        ghost_sent = max(x["sent"] for x in t)
        halo_nodes = 2 * worst["row_active"] * worst["neighbours"] / 2
        neighbours = 2
        own_nodes = max(x["nodes"] for x in t)
    else:
        own, ghosts, ghost_sent, halo_nodes, neighbours, own_nodes = case.N, 0, 0, 0, 0, case.n / case.nf
    local = own + ASSUMED["ghost_cost"] * ghosts
    t_points = cal["t_pt"] * local
    if P == 1:
        t_fin = (s + 1) * cal["c_res"] * case.N
    else:
        t_fin = (own + ghosts) * (s * (cal["c_eval"] + cal["c_res"]) + cal["c_res"])
    # --- solve: factorisations and Krylov iterations on the own unknowns
    K = cal["K1"] * (1 + a * math.log2(P))
    n_own = own_nodes * case.nf
    t_fact = k * cal["fact_per_newton"] * cal["t_f_u"] * n_own
    t_kry = k * K * cal["t_it_u"] * n_own
    mc = mem_contention(P)
    t_solve = (t_fact + t_kry) * mc
    # --- whole-grid work (today: every grid node on every process; dist/boxes: own + ghost nodes)
    t_node = ASSUMED["t_node_2d"] if case.dim == 2 else ASSUMED["t_node_3d"]
    if variant == "today" or P == 1:
        t_grid = t_node * case.grid_nodes
    else:
        t_grid = t_node * (case.grid_nodes / P + halo_nodes * 4)
    # --- communication
    t_comm, msgs, bytes_ = 0.0, 0, 0.0
    if P > 1:
        L = log2c(P)
        bn, bc = bw_neighbour(P), bw_collective(P)
        n_eval = 3 * k  # residual and Jacobian evaluations per step (about 3 per Newton iteration)
        red = ASSUMED["reductions_per_step"] + 2 * n_eval + k * K + 3 * s  # the program's own
        red += k * K * ASSUMED["gmres_reductions"] + k * ASSUMED["newton_reductions"]  # PETSc's
        t_red = red * 2 * L * alpha
        msgs += red * 2 * L
        # record exchanges: migrate, ghosts, P2G sums, eta_bar sums (+ active flags today)
        ex = 4
        ghost_bytes = ghost_sent * case.record
        sums_bytes = 4 * halo_nodes / 2 * (1 + 2 * case.dim + 1) * 8
        win_bytes = n_eval * 3.5 * halo_nodes / 2 * case.nf * 8
        halo_kry = k * K * (halo_nodes * case.nf * 8)  # PETSc's MatMult halo per Krylov iteration
        if variant == "today":
            t_ex = ex * (3 * L * alpha + neighbours * alpha) + (P - 1) * alpha + 2 * L * alpha
            msgs += ex * (3 * L + neighbours) + (P - 1) + 2 * L
            flags = case.grid_nodes / 32 * 8
            gather_all = (s + 1) * case.n * 8  # received by every process, each solve and the last
            t_all = (s + 1) * (min(L, P - 1) * alpha) + (gather_all + flags) / bc
            msgs += (s + 1) * L
            bytes_ = ghost_bytes + sums_bytes + win_bytes + flags + gather_all * (P - 1) / P
            t_comm = t_red + t_ex + t_all + (ghost_bytes + sums_bytes + win_bytes) / bn
        else:
            t_ex = ex * neighbours * alpha + L * alpha  # neighbour-only counts; a prefix sum of numbering
            msgs += ex * neighbours + L
            ghost_unknowns = (s + 1) * halo_nodes * case.nf * 8
            t_all = (s + 1) * neighbours * alpha + ghost_unknowns / bn
            msgs += (s + 1) * neighbours
            bytes_ = ghost_bytes + sums_bytes + win_bytes + ghost_unknowns
            t_comm = t_red + t_ex + t_all + (ghost_bytes + sums_bytes + win_bytes) / bn
        t_comm += k * K * (neighbours * alpha) + halo_kry / bn  # PETSc halo exchanges
        msgs += k * K * neighbours
        bytes_ += halo_kry
    total = t_points + t_fin + t_solve + t_grid + t_comm
    if detail:
        return dict(total=total, points=t_points + t_fin, solve=t_solve, grid=t_grid, comm=t_comm,
                    own=own, ghosts=ghosts, K=K, msgs=msgs, bytes=bytes_, mc=mc)
    return total


# ---------------------------------------------------------------------------------------------------
# Checks against the measurements
# ---------------------------------------------------------------------------------------------------
def validate_2d():
    """Predicted against measured per-phase times on 2 processes (the P = 1 run is the calibration)."""
    case = Case("paper", 2, 1.0)
    rows = []
    for state in ("elastic", "cracked"):
        cal = calibrate_2d(state, case)
        m1, m2 = MEASURED_2D[state][1], MEASURED_2D[state][2]
        # On the measuring machine: 2 cores, one node, memory shared as measured (no contention term).
        saved = dict(ASSUMED)
        ASSUMED["node_mem_bw"] = 1e30
        d = step_time(case, cal, 2, "today", detail=True)
        ASSUMED.clear()
        ASSUMED.update(saved)
        other = m1["step"] - m1["setup"] - m1["assembly"] - m1["petsc"]
        frac_other = other / (m1["setup"] + m1["assembly"] + other)
        loops = cal["t_pt"] * (d["own"] + d["ghosts"])
        pred_sa = loops * (1 - frac_other)
        s = ASSUMED["solves_per_step"]
        fin = (d["own"] + d["ghosts"]) * (s * (cal["c_eval"] + cal["c_res"]) + cal["c_res"])
        pred_petsc = d["solve"] + fin + d["comm"] + d["grid"]
        rows.append((state, MEASURED_2D[state]["steps"], "set-up + assembly", pred_sa,
                     m2["setup"] + m2["assembly"]))
        rows.append((state, "", "PETSc column", pred_petsc, m2["petsc"]))
        rows.append((state, "", "step", d["total"], m2["step"]))
        rows.append((state, "", "step, 1 x 2 / 2 x 1", m1["step"] / d["total"], m1["step"] / m2["step"]))
    return rows


def bytes_model(case, P, solves, k, whole_residual):
    """kB sent per process and step through the program's own exchanges (partition.rs, processes.rs,
    petsc/vector.rs), per process, and of them the unknowns' window gathers."""
    t = band_traffic(case, P)
    out = []
    n_eval = 3 * k
    for r, x in enumerate(t):
        ghost = x["sent"] * case.record
        own_u = x["nodes"] * case.nf
        gather_all = solves * own_u * (P - 1) * 8
        win = n_eval * x["neighbours"] * 3.5 * x["row_active"] * case.nf * 8
        sums = x["neighbours"] * 4 * x["row_active"] * (1 + 2 * case.dim + 1) * 8
        flags = math.ceil(x["nodes"] / 32) * 8 * (P - 1)
        resid = solves * case.n * 8 if whole_residual else 0.0
        red = 10e3  # the constraint and device nodes' values (complete_beyond_windows) and reductions
        out.append(((ghost + gather_all + win + sums + flags + resid + red) / 1e3, win / 1e3))
    return out


def fit_solves(case, k, measured, whole_residual):
    """The SNES solves per step that make the 2-process bytes match (least squares over processes)."""
    best = None
    for i in range(100, 600):
        s = i / 100
        pred = bytes_model(case, 2, s, k, whole_residual)
        err = sum((p[0] - m[0]) ** 2 for p, m in zip(pred, measured[2]))
        if best is None or err < best[0]:
            best = (err, s)
    return best[1]


def validate_bytes():
    out = []
    for name, case, meas, newton, steps, whole in (
            ("paper size (3 steps)", Case("paper", 2, 1.0), BYTES_PAPER, NEWTON_PAPER_3, 3, True),
            ("CT demo (10 steps)", Case("demo", 2, 4.0, margin=3, notch_w=8.0), BYTES_DEMO,
             NEWTON_DEMO_10, 10, False)):
        k2 = newton[2] / steps
        s = fit_solves(case, k2, meas, whole)
        for P in (2, 3, 4):
            pred = bytes_model(case, P, s, newton[P] / steps, whole)
            out.append((name, P, s, pred, meas[P]))
    return out


# ---------------------------------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------------------------------
def fmt_t(t):
    if t is None:
        return "-"
    if t >= 100:
        return f"{t:.0f}"
    if t >= 10:
        return f"{t:.1f}"
    if t >= 1:
        return f"{t:.2f}"
    if t >= 0.01:
        return f"{t:.3f}"
    return f"{t * 1e3:.2f} ms"


def strong_table(case, cal, title):
    lines = [f"| P | today: s/step | speed-up | dist: s/step | speed-up | boxes: s/step | speed-up |",
             "|---|---|---|---|---|---|---|"]
    t1 = step_time(case, cal, 1, "today")
    for P in PS:
        cells = []
        for v in ("today", "dist", "boxes"):
            t = step_time(case, cal, P, v)
            cells += [fmt_t(t), "-" if t is None else f"{t1 / t:.1f}"]
        lines.append(f"| {P} | " + " | ".join(cells) + " |")
    return lines


def breakdown_table(case, cal, variant, Ps):
    lines = ["| P | points (own + ghosts) | ghost share | point loops | solve (K/Newton) | whole grid | communication | latency hops | MB sent | step |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for P in Ps:
        d = step_time(case, cal, P, variant, detail=True)
        if d is None:
            lines.append(f"| {P} | bands need P <= {case.ny} | | | | | | | | |")
            continue
        lines.append(
            f"| {P} | {d['own']:,.0f} + {d['ghosts']:,.0f} | {d['ghosts'] / d['own']:.2f} | "
            f"{fmt_t(d['points'])} | {fmt_t(d['solve'])} ({d['K']:.1f}) | {fmt_t(d['grid'])} | "
            f"{fmt_t(d['comm'])} | {d['msgs']:,.0f} | {d['bytes'] / 1e6:.2f} | {fmt_t(d['total'])} |")
    return lines


def weak_cases(dim):
    """Weak scaling: the cell size shrinks with P so that every process keeps the points of P_ref's
    share: 2D the paper size at P = 16 (h = 1 mm x sqrt(16/P)), 3D the 50 mm plate at P = 512."""
    out = []
    for P in PS:
        if dim == 2:
            h = 1.0 * math.sqrt(16 / P)
            c = Case(f"2D h={h:.3g}", 2, h, notch_w=10.0)
        else:
            h = (512 / P) ** (1 / 3)
            c = Case(f"3D h={h:.3g}", 3, h, thickness=50.0)
        out.append((P, h, c))
    return out


def weak_table(dim, state="cracked"):
    lines = ["| P | h (mm) | points | unknowns | K/Newton (P = 1) | today: s/step | efficiency | dist | efficiency | boxes | efficiency |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    base = None
    for P, h, c in weak_cases(dim):
        cal = calibrate_2d(state, Case("paper", 2, 1.0)) if dim == 2 else calibrate_3d(c)
        if dim == 2:
            cal = dict(cal)
            cal["K1"] = cal["K1"] * k_of_h(h) / k_of_h(1.0)  # Krylov iterations follow the cell size
        cells = []
        t1 = step_time(c, cal, 1, "today")
        if base is None:
            base = t1
        for v in ("today", "dist", "boxes"):
            t = step_time(c, cal, P, v)
            cells += [fmt_t(t), "-" if t is None else f"{base / t:.2f}"]
        lines.append(f"| {P} | {h:.3g} | {c.N:,} | {c.n:,} | {cal['K1']:.1f} | " + " | ".join(cells) + " |")
    return lines


def sensitivity_table(case, cal):
    """Speed-ups at P = 16 and 128 with one assumption changed at a time."""
    lines = ["| assumption changed | P = 16 today | P = 16 dist | P = 128 today | P = 128 dist | P = 512 boxes |",
             "|---|---|---|---|---|---|"]

    def row(name, k_growth=None, **kw):
        saved = dict(ASSUMED)
        ASSUMED.update(kw)
        t1 = step_time(case, cal, 1, "today", k_growth=k_growth)
        cells = []
        for P, v in ((16, "today"), (16, "dist"), (128, "today"), (128, "dist"), (512, "boxes")):
            t = step_time(case, cal, P, v, k_growth=k_growth)
            cells.append("-" if t is None else f"{t1 / t:.1f}")
        ASSUMED.clear()
        ASSUMED.update(saved)
        lines.append(f"| {name} | " + " | ".join(cells) + " |")

    row(f"none (the tables above; Krylov growth a = {cal['a']:.3f} per doubling)")
    row("Krylov iterations flat in P (a = 0)", k_growth=0.0)
    row("a = 0.043 (the 2D elastic steps' value)", k_growth=0.043)
    row("a = 0.5 (twice the 2D cracked steps' value)", k_growth=0.5)
    row("whole-grid loops 3x dearer", t_node_2d=3 * ASSUMED["t_node_2d"], t_node_3d=3 * ASSUMED["t_node_3d"])
    row("latency 5 us instead of 1.5", alpha=5e-6)
    row("no memory contention on a node", node_mem_bw=1e30)
    row("ghosts cost half an own point", ghost_cost=0.5)
    return lines


def all_tables():
    paper = Case("paper", 2, 1.0)
    ct3 = Case("3D T=50", 3, 1.0, thickness=50.0)
    cal_e, cal_c = calibrate_2d("elastic", paper), calibrate_2d("cracked", paper)
    cal3 = calibrate_3d(ct3)
    T = {}
    T["inputs"] = [
        "| quantity | 2D paper size | 3D plate T = 50 mm |",
        "|---|---|---|",
        f"| points N | {paper.N:,} | {ct3.N:,} |",
        f"| unknowns n (3 or 4 per active node, at the start) | {paper.n:,} | {ct3.n:,} |",
        f"| grid nodes (every process holds all today) | {paper.grid_nodes:,} | {ct3.grid_nodes:,} |",
        f"| cell rows of the grid (bands: P at most) | {paper.ny} | {ct3.ny} |",
        f"| points per full cell row | {max(paper.rows):,} | {max(ct3.rows):,} |",
        f"| point record (B) | {paper.record} | {ct3.record} |",
        f"| point work, core-us per point and step (elastic / cracked) | {cal_e['t_pt'] * 1e6:.2f} / {cal_c['t_pt'] * 1e6:.2f} | {cal3['t_pt'] * 1e6:.1f} (cracking average) |",
        f"| factorisation, core-us per unknown | {cal_e['t_f_u'] * 1e6:.2f} / {cal_c['t_f_u'] * 1e6:.2f} | {cal3['t_f_u'] * 1e6:.1f} |",
        f"| Krylov iteration, core-us per unknown | {cal_e['t_it_u'] * 1e6:.3f} / {cal_c['t_it_u'] * 1e6:.3f} | {cal3['t_it_u'] * 1e6:.2f} |",
        f"| Newton per step; Krylov per Newton at P = 1 | {cal_e['k']:.2f}; {cal_e['K1']:.2f} / {cal_c['k']:.2f}; {cal_c['K1']:.2f} | {cal3['k']:.2f}; {cal3['K1']:.1f} |",
        f"| factorisations per Newton iteration | 1 (lag 1, as measured) | {cal3['fact_per_newton']:.2f} (lag 2) |",
        f"| Krylov growth per doubling of P (a) | {cal_e['a']:.3f} / {cal_c['a']:.3f} (measured at P = 2) | {cal3['a']:.2f} (assumed) |",
        f"| one core, s per step (model, P = 1) | {step_time(paper, cal_e, 1, 'today'):.2f} / {step_time(paper, cal_c, 1, 'today'):.2f} | {step_time(ct3, cal3, 1, 'today'):.0f} |",
    ]
    T["strong2d_elastic"] = strong_table(paper, cal_e, "2D elastic")
    T["strong2d_cracked"] = strong_table(paper, cal_c, "2D cracked")
    T["strong3d"] = strong_table(ct3, cal3, "3D")
    T["break2d_today"] = breakdown_table(paper, cal_c, "today", [2, 16, 128, 216])
    T["break2d_dist"] = breakdown_table(paper, cal_c, "dist", [2, 16, 128, 216])
    T["break2d_boxes"] = breakdown_table(paper, cal_c, "boxes", [16, 128, 512])
    T["break3d_today"] = breakdown_table(ct3, cal3, "today", [2, 16, 128, 216])
    T["break3d_dist"] = breakdown_table(ct3, cal3, "dist", [2, 16, 128, 216])
    T["break3d_boxes"] = breakdown_table(ct3, cal3, "boxes", [16, 128, 512])
    T["weak2d"] = weak_table(2)
    T["weak3d"] = weak_table(3)
    T["sens2d"] = sensitivity_table(paper, cal_c)
    T["sens3d"] = sensitivity_table(ct3, cal3)
    v = ["| state (steps) | quantity | model, 2 x 1 | measured, 2 x 1 | model / measured |",
         "|---|---|---|---|---|"]
    for state, steps, q, p, m in validate_2d():
        label = f"{state} ({steps})" if steps else ""
        v.append(f"| {label} | {q} | {p:.3f} | {m:.3f} | {p / m:.2f} |")
    T["validate_time"] = v
    b = ["| case | P | solves per step (fitted at P = 2) | model, kB per process | measured, kB per process | model / measured (largest) |",
         "|---|---|---|---|---|---|"]
    for name, P, s, pred, meas in validate_bytes():
        pm = ", ".join(f"{p[0]:.0f}" for p in pred)
        mm = ", ".join(f"{m[0]}" for m in meas)
        ratio = max(p[0] for p in pred) / max(m[0] for m in meas)
        b.append(f"| {name} | {P} | {s:.2f} | {pm} | {mm} | {ratio:.2f} |")
    T["validate_bytes"] = b
    c = Case("paper", 2, 1.0)
    tr = band_traffic(c, 2)
    T["validate_ghosts"] = [f"ghost copies per step on 2 processes: model {sum(x['recv'] for x in tr):,.0f} "
                            f"(the rule alone {sum(x['recv'] for x in tr) / GF:,.0f}, calibrated by x{GF:.2f}), "
                            f"measured {GHOSTS_P2:,}"]
    return T


def speedups(case, cal, variant):
    t1 = step_time(case, cal, 1, "today")
    out = []
    for P in PS:
        t = step_time(case, cal, P, variant)
        out.append(None if t is None else t1 / t)
    return out


def plot(path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    paper = Case("paper", 2, 1.0)
    ct3 = Case("3D T=50", 3, 1.0, thickness=50.0)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), sharey=True)
    for ax, (title, case, cal) in zip(axes, (
            ("2D paper-size CT, cracked steps (155,600 points)", paper, calibrate_2d("cracked", paper)),
            ("3D CT plate, T = 50 mm, 1 mm cells (15.6 M points)", ct3, calibrate_3d(ct3)))):
        ax.loglog(PS, PS, "k:", label="ideal")
        for v, style, label in (("today", "o-", "today (replicated grid, gather of all unknowns)"),
                                ("dist", "s-", "distributed grid (issue 46 item 2), bands"),
                                ("boxes", "^--", "distributed grid, boxes (process grid)")):
            s = speedups(case, cal, v)
            xs = [p for p, y in zip(PS, s) if y is not None]
            ys = [y for y in s if y is not None]
            ax.loglog(xs, ys, style, label=label)
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("processes P (one core each)")
        ax.set_xticks(PS)
        ax.set_xticklabels([str(p) for p in PS])
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("speed-up T(1) / T(P), model")
    axes[0].legend(fontsize=8, loc="upper left")
    fig.suptitle("Scaling model of one implicit step (tools/scaling_model/model.py, docs/scaling.md)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def write_doc(tables, path):
    with open(path) as f:
        text = f.read()
    for name, lines in tables.items():
        pat = re.compile(rf"(<!-- model:{name} -->\n)(.*?)(<!-- /model:{name} -->)", re.S)
        if not pat.search(text):
            continue
        text = pat.sub(lambda m: m.group(1) + "\n".join(lines) + "\n" + m.group(3), text)
    with open(path, "w") as f:
        f.write(text)
    print(f"rewrote the tables in {path}")


def compare_measured(path, skip=1):
    """Mean per-step times per P of a collected series (scripts/slurm/ct-scaling.sh) against the model
    recalibrated on nothing: the speed-ups are compared, the P = 1 run sets T(1)."""
    per = defaultdict(list)
    with open(path) as f:
        for row in csv.DictReader(f):
            if int(row["step"]) <= skip:
                continue
            per[int(row["processes"])].append(row)
    if 1 not in per:
        sys.exit("the series has no P = 1 run: speed-ups need it")
    mean = {P: sum(float(r["wall_total"]) for r in rows) / len(rows) for P, rows in per.items()}
    paper = Case("paper", 2, 1.0)
    cal = calibrate_2d("elastic", paper)
    t1 = step_time(paper, cal, 1, "today")
    print("| P | measured s/step | measured speed-up | model speed-up (today, elastic steps) | Newton/step | Krylov/Newton |")
    print("|---|---|---|---|---|---|")
    for P in sorted(mean):
        t = step_time(paper, cal, P, "today")
        rows = per[P]
        k = sum(float(r["newton_its"]) for r in rows) / len(rows)
        K = sum(float(r["linear_its"]) for r in rows) / max(1e-9, sum(float(r["newton_its"]) for r in rows))
        print(f"| {P} | {mean[P]:.3f} | {mean[1] / mean[P]:.1f} | {'-' if t is None else f'{t1 / t:.1f}'} | {k:.2f} | {K:.1f} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--write-doc", action="store_true", help="rewrite the tables in docs/scaling.md")
    ap.add_argument("--plot", action="store_true", help="write docs/img/scaling_model.png")
    ap.add_argument("--measured", metavar="CSV", help="a collected series (scripts/slurm/ct-scaling.sh)")
    args = ap.parse_args()
    if args.measured:
        compare_measured(args.measured)
        return
    tables = all_tables()
    for name, lines in tables.items():
        print(f"## {name}")
        print("\n".join(lines))
        print()
    if args.write_doc:
        write_doc(tables, os.path.join(ROOT, "docs", "scaling.md"))
    if args.plot:
        plot(os.path.join(ROOT, "docs", "img", "scaling_model.png"))


if __name__ == "__main__":
    main()
