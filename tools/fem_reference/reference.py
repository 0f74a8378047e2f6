#!/usr/bin/env python3
"""Independent FEM reference solutions for mpm_concrete (issue 8, item 4).

Two small-strain, linear elastic, plane strain, quasi-static problems solved
with scikit-fem on structured, geometrically aligned and graded meshes of
biquadratic (9-node, ElementQuad2) quadrilaterals:

* ``ct-elastic``  -- the compact tension geometry (200 x 200 mm, notch
  [0,110] x [95,105]) opened by a prescribed displacement of the lower notch
  face next to the mouth;
* ``cantilever``  -- a 100 x 10 mm cantilever clamped at x = 0 with a uniform
  shear traction on the tip edge x = 100 (resultant -1 N per mm thickness).

Units: mm, s, N, MPa, t.  Forces are per mm of thickness.

Every problem is solved on a sequence of meshes; each level doubles the number
of elements of every segment of the tensor-product grid and keeps the grading
function, so the meshes are nested.  The values of the finest level are
written; the convergence of every quantity (Richardson-style error estimate)
goes to ``convergence.json``.

Usage::

    python tools/fem_reference/reference.py --out tests/data/fem
    python tools/fem_reference/reference.py --out /tmp/fem-quick --quick
"""

import os

# one BLAS / OpenMP thread: deterministic and gentle on a shared machine
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json
import math
import platform
import sys
import tempfile
import time

import numpy as np
import scipy
import scipy.sparse.linalg as spla
import skfem
from skfem import (Basis, BilinearForm, ElementQuad2, ElementVector,
                   FacetBasis, LinearForm, MeshQuad, asm, condense)
from skfem.helpers import sym_grad, trace

# ---------------------------------------------------------------- material
E_MOD = 36000.0  # MPa
NU = 0.18
LAMBDA = E_MOD * NU / ((1.0 + NU) * (1.0 - 2.0 * NU))  # plane strain = 3D Lame
MU = E_MOD / (2.0 * (1.0 + NU))

GEOM_TOL = 1e-9  # mm, for locating facets / points on grid lines


def stress_from_strain(eps):
    """sigma = 2 mu eps + lambda tr(eps) I for a (2, 2, ...) strain array."""
    tr = eps[0, 0] + eps[1, 1]
    sig = 2.0 * MU * eps
    sig[0, 0] = sig[0, 0] + LAMBDA * tr
    sig[1, 1] = sig[1, 1] + LAMBDA * tr
    return sig


@BilinearForm
def elasticity_form(u, v, w):
    eu = sym_grad(u)
    ev = sym_grad(v)
    # sigma(u) : eps(v) written out, so that no helper of the model library
    # is needed
    tr_u = trace(eu)
    return (2.0 * MU * (eu[0, 0] * ev[0, 0] + eu[1, 1] * ev[1, 1]
                        + 2.0 * eu[0, 1] * ev[0, 1])
            + LAMBDA * tr_u * trace(ev))


# ------------------------------------------------------------------- meshes
def graded_segment(a, b, n, left, right, beta):
    """n elements on [a, b], power-graded (exponent beta) towards the ends
    flagged ``left`` / ``right``; uniform if neither is flagged.

    Double-sided grading maps the two halves of [0, 1] separately, so n must
    be even in that case.  The smallest element at a graded end has the size
    l * (1/m)^beta, with l and m the length and element count of the graded
    part (the whole segment, or its half for double-sided grading).
    """
    s = np.linspace(0.0, 1.0, n + 1)
    if left and right:
        assert n % 2 == 0
        g = np.where(s <= 0.5,
                     0.5 * (2.0 * s) ** beta,
                     1.0 - 0.5 * (2.0 * (1.0 - s)) ** beta)
    elif left:
        g = s ** beta
    elif right:
        g = 1.0 - (1.0 - s) ** beta
    else:
        g = s
    g[0], g[-1] = 0.0, 1.0
    return a + (b - a) * g


def graded_axis(segments, level, beta):
    """Concatenate graded segments; ``segments`` holds tuples
    (a, b, n0, left, right) with n0 the element count at level 0."""
    parts = []
    for (a, b, n0, left, right) in segments:
        n = n0 * 2 ** level
        parts.append(graded_segment(a, b, n, left, right, beta))
    out = np.concatenate([parts[0]] + [p[1:] for p in parts[1:]])
    assert np.all(np.diff(out) > 0.0)
    return out


# CT: breakpoints at the ends of the prescribed segments (x = 30), the notch
# end (x = 110) and the notch faces (y = 95, 105), and at the coordinates of
# the evaluation points (x = 50, 150, 160; y = 30, 50, 100, 150), so that
# every point is a mesh vertex at every level (its position relative to the
# elements does not change with refinement, which keeps the convergence of the
# point stresses monotone).  Singular points (grading targets): (30, 95),
# (30, 105) (ends of the prescribed segments), (110, 95), (110, 105)
# (re-entrant notch corners) and (0, 105) (clamped / free corner at the
# mouth; (0, 95) is a sliding / free right angle, graded as well since the
# x = 0 end is shared).  Tuples: (a, b, elements at level 0, graded at a,
# graded at b).
CT_X_SEGMENTS = [(0.0, 30.0, 4, True, True),
                 (30.0, 50.0, 3, True, False),
                 (50.0, 110.0, 6, False, True),
                 (110.0, 150.0, 4, True, False),
                 (150.0, 160.0, 1, False, False),
                 (160.0, 200.0, 2, False, False)]
CT_Y_SEGMENTS = [(0.0, 30.0, 2, False, False),
                 (30.0, 50.0, 1, False, False),
                 (50.0, 95.0, 4, False, True),
                 (95.0, 100.0, 2, True, False),
                 (100.0, 105.0, 2, False, True),
                 (105.0, 150.0, 4, True, False),
                 (150.0, 200.0, 2, False, False)]
CT_NOTCH = (0.0, 110.0, 95.0, 105.0)
# Power grading exponent: the reaction error then falls like n^-(2 lambda
# beta) = n^-3 for the lambda = 1/2 singularities (n^-4 would need beta = 4
# but gives extreme aspect ratios); the levels run in the full mode.
CT_BETA = 3.0
CT_LEVELS = [1, 2, 3, 4]

# Cantilever: graded towards the clamp (corner singularities at (0, 0) and
# (0, 10)); breakpoints at the evaluation points (x = 25, 50; y = 1.25, 5,
# 8.75); graded towards the tip too, where the traction jumps at the corners
# (100, 0) and (100, 10).
CANT_L, CANT_H = 100.0, 10.0
CANT_X_SEGMENTS = [(0.0, 5.0, 2, True, False),
                   (5.0, 25.0, 2, False, False),
                   (25.0, 50.0, 2, False, False),
                   (50.0, 90.0, 3, False, False),
                   (90.0, 100.0, 1, False, True)]
CANT_Y_SEGMENTS = [(0.0, 1.25, 1, True, False),
                   (1.25, 5.0, 1, False, False),
                   (5.0, 8.75, 1, False, False),
                   (8.75, 10.0, 1, False, True)]
# Milder grading: the clamp corners are weakly singular and the quantities
# are far from them.
CANT_BETA = 2.0
CANT_LEVELS = [2, 3, 4, 5]


def ct_mesh(level, beta):
    x = graded_axis(CT_X_SEGMENTS, level, beta)
    y = graded_axis(CT_Y_SEGMENTS, level, beta)
    m = MeshQuad.init_tensor(x, y)
    c = m.p[:, m.t].mean(axis=1)  # element centroids
    x0, x1, y0, y1 = CT_NOTCH
    in_notch = (c[0] > x0) & (c[0] < x1) & (c[1] > y0) & (c[1] < y1)
    return m.remove_elements(np.nonzero(in_notch)[0])


def cantilever_mesh(level, beta):
    x = graded_axis(CANT_X_SEGMENTS, level, beta)
    y = graded_axis(CANT_Y_SEGMENTS, level, beta)
    return MeshQuad.init_tensor(x, y)


# ------------------------------------------------------------ evaluation
def element_sizes(mesh):
    """Smallest and largest edge length of the rectangles."""
    pts = mesh.p[:, mesh.t]  # (2, 4, nel)
    dx = pts[0].max(axis=0) - pts[0].min(axis=0)
    dy = pts[1].max(axis=0) - pts[1].min(axis=0)
    return float(min(dx.min(), dy.min())), float(max(dx.max(), dy.max()))


def cells_containing(mesh, point, tol=1e-9):
    """All (axis aligned, rectangular) elements whose closure holds point."""
    pts = mesh.p[:, mesh.t]
    xmin, xmax = pts[0].min(axis=0), pts[0].max(axis=0)
    ymin, ymax = pts[1].min(axis=0), pts[1].max(axis=0)
    px, py = point
    hit = ((xmin - tol <= px) & (px <= xmax + tol)
           & (ymin - tol <= py) & (py <= ymax + tol))
    cells = np.nonzero(hit)[0]
    if cells.size == 0:
        raise ValueError(f"point {point} is outside the mesh")
    return cells


def evaluate_at(basis, u, point):
    """Displacement and displacement gradient of the FE field at ``point``.

    The point is located in every element whose closure contains it; the
    value and gradient are evaluated there from the element's basis
    functions (mapped to the reference element) and averaged over those
    elements.  The displacement is continuous, so the average only matters
    for the gradient (which jumps across element edges of a C0 field)."""
    mesh = basis.mesh
    cells = cells_containing(mesh, point)
    X = np.array(point, dtype=float).reshape(2, 1, 1)
    X = np.repeat(X, cells.size, axis=1)  # (2, ncells, 1)
    # scikit-fem's default Newton tolerance (1e-12 in reference coordinates)
    # is below round-off for the tiniest graded elements away from the
    # origin; 1e-10 is still far below any discretisation error
    ref = basis.mapping.invF(X, tind=cells, newton_tol=1e-10)
    # clip round-off outside the reference square [0, 1]^2
    ref = np.clip(ref, 0.0, 1.0)
    val = np.zeros((2, cells.size))
    grad = np.zeros((2, 2, cells.size))
    for k in range(basis.Nbfun):
        phi = basis.elem.gbasis(basis.mapping, ref, k, tind=cells)[0]
        coef = u[basis.element_dofs[k, cells]]  # (ncells,)
        val += phi.value[:, :, 0] * coef
        grad += phi.grad[:, :, :, 0] * coef
    return val.mean(axis=1), grad.mean(axis=2), cells.size


def probe_displacement(basis, u, point):
    """Displacement by scikit-fem's own probes (cross-check), or None where
    its inverse mapping does not reach its default tolerance (round-off in
    the tiniest graded elements)."""
    try:
        P = basis.probes(np.array(point, dtype=float).reshape(2, 1))
    except Exception:  # noqa: BLE001 -- scikit-fem raises a bare Exception
        return None
    return P @ u


def point_quantities(basis, u, point, wanted):
    val, grad, ncell = evaluate_at(basis, u, point)
    pv = probe_displacement(basis, u, point)
    scale = max(np.max(np.abs(val)), 1e-300)
    if pv is not None and np.max(np.abs(pv - val)) > 1e-8 * scale + 1e-15:
        raise RuntimeError(f"probe mismatch at {point}: {pv} vs {val}")
    eps = 0.5 * (grad + grad.T)
    sig = stress_from_strain(eps)
    allq = {"ux": val[0], "uy": val[1], "sigma_xx": sig[0, 0],
            "sigma_yy": sig[1, 1], "sigma_xy": sig[0, 1]}
    return {q: float(allq[q]) for q in wanted}


# ---------------------------------------------------------------- solving
def solve_linear(K, f, u_prescribed, D):
    """Solve K u = f with u[D] = u_prescribed[D]: sparse LU (SuperLU with
    COLAMD ordering, deterministic) of the reduced system.

    The strongly graded meshes (aspect ratios up to ~3e4 in the CT, ~500 in
    the cantilever) set a round-off floor of ~1e-7 N on the reactions (and
    on the relative residual of the small-load cantilever); iterative
    refinement does not lower it, since it is the floor of evaluating K u
    itself."""
    A, b, x, I = condense(K, f, x=u_prescribed, D=D)
    A = A.tocsc()
    u = u_prescribed.copy()
    u[I] = spla.spsolve(A, b, permc_spec="COLAMD")
    res = np.linalg.norm(A @ u[I] - b) / max(np.linalg.norm(b), 1e-300)
    return u, res


def facet_dofs(basis, test):
    facets = basis.mesh.facets_satisfying(test, boundaries_only=True)
    if facets.size == 0:
        raise RuntimeError("empty facet set")
    d = basis.get_dofs(facets)
    return d.all("u^1"), d.all("u^2"), facets


CT_DISP_POINTS = [(0.0, 0.0), (0.0, 200.0), (200.0, 0.0), (200.0, 200.0),
                  (150.0, 100.0), (50.0, 50.0), (160.0, 150.0)]
CT_STRESS_POINTS = [(50.0, 50.0), (150.0, 100.0), (160.0, 150.0),
                    (150.0, 30.0)]
CT_LOAD_UY = -0.01  # mm
# u_x is free on the load set, so the support carries the whole x-resultant,
# which vanishes by equilibrium
CT_ZERO = ("support_fx",)


def solve_ct(level, beta):
    t0 = time.time()
    mesh = ct_mesh(level, beta)
    basis = Basis(mesh, ElementVector(ElementQuad2()), intorder=4)
    K = asm(elasticity_form, basis)
    tol = GEOM_TOL
    load_x, load_y, _ = facet_dofs(
        basis, lambda p: (np.abs(p[1] - 95.0) < tol) & (p[0] <= 30.0 + tol))
    sup_x, sup_y, _ = facet_dofs(
        basis, lambda p: (np.abs(p[1] - 105.0) < tol) & (p[0] <= 30.0 + tol))
    u0 = np.zeros(basis.N)
    u0[load_y] = CT_LOAD_UY
    D = np.unique(np.concatenate([load_y, sup_x, sup_y]))
    u, res = solve_linear(K, np.zeros(basis.N), u0, D)
    r = K @ u  # force the constraints exert on the body, per dof
    values = {
        "load_fy": float(r[load_y].sum()),
        "support_fx": float(r[sup_x].sum()),
        "support_fy": float(r[sup_y].sum()),
    }
    checks = {
        # u_x is free on the load set, so its x-reaction vanishes (~0)
        "load_fx_free_dofs": float(r[load_x].sum()),
        "relative_residual": float(res),
        # the body is in equilibrium: load_fy + support_fy = 0
        "equilibrium_fy": float(values["load_fy"] + values["support_fy"]),
    }
    for pt in CT_DISP_POINTS:
        for q, v in point_quantities(basis, u, pt, ["ux", "uy"]).items():
            values[f"{q}@({pt[0]:g},{pt[1]:g})"] = v
    for pt in CT_STRESS_POINTS:
        for q, v in point_quantities(
                basis, u, pt, ["sigma_xx", "sigma_yy", "sigma_xy"]).items():
            values[f"{q}@({pt[0]:g},{pt[1]:g})"] = v
    hmin, hmax = element_sizes(mesh)
    info = {
        "level": level,
        "element": "ElementVector(ElementQuad2) (9-node biquadratic quads)",
        "elements": int(mesh.t.shape[1]),
        "dofs": int(basis.N),
        "h_min": hmin,
        "h_max": hmax,
        "grading_beta": beta,
        "seconds": round(time.time() - t0, 2),
        "checks": checks,
        "values": values,
    }
    return info


CANT_DISP_POINTS = [(100.0, 5.0), (100.0, 0.0), (100.0, 10.0), (50.0, 5.0),
                    (25.0, 5.0)]
CANT_SXX_POINTS = [(25.0, 8.75), (25.0, 1.25), (50.0, 8.75)]
CANT_SXY_POINTS = [(25.0, 5.0)]
CANT_P = -1.0  # N per mm thickness (resultant in y)
# zero by equilibrium (clamp_fx) and by antisymmetry about y = 5 (u_x on the
# mid-line)
CANT_ZERO = ("clamp_fx", "ux@(100,5)", "ux@(50,5)", "ux@(25,5)")


def edge_load_quad2(basis, facets, ty):
    """Consistent nodal forces of a uniform traction (0, ty) on straight
    boundary facets for the 9-node quadrilateral: the trace of the element
    on an edge is the quadratic Lagrange interpolant through its end
    vertices and midpoint, whose shape functions integrate to le/6, le/6 and
    2 le/3."""
    mesh = basis.mesh
    f = np.zeros(basis.N)
    v0, v1 = mesh.facets[0, facets], mesh.facets[1, facets]
    le = np.linalg.norm(mesh.p[:, v1] - mesh.p[:, v0], axis=0)
    np.add.at(f, basis.nodal_dofs[1, v0], ty * le / 6.0)
    np.add.at(f, basis.nodal_dofs[1, v1], ty * le / 6.0)
    np.add.at(f, basis.facet_dofs[1, facets], ty * le * 2.0 / 3.0)
    return f


def facet_basis_load_difference(mesh, elem, facets, ty, f):
    """Cross-check of edge_load_quad2 with scikit-fem's FacetBasis assembly
    of the same traction; None where FacetBasis cannot be built (its inverse
    mapping misses its fixed 1e-12 tolerance by round-off on the tiniest
    graded elements away from the origin)."""
    try:
        fbasis = FacetBasis(mesh, elem, facets=facets, intorder=4)
    except Exception:  # noqa: BLE001 -- scikit-fem raises a bare Exception
        return None

    @LinearForm
    def traction(v, w):
        return ty * v[1]

    diff = float(np.max(np.abs(asm(traction, fbasis) - f)))
    if diff > 1e-12:
        raise RuntimeError(f"consistent tip load differs from FacetBasis: {diff}")
    return diff


def solve_cantilever(level, beta):
    t0 = time.time()
    mesh = cantilever_mesh(level, beta)
    elem = ElementVector(ElementQuad2())
    basis = Basis(mesh, elem, intorder=4)
    K = asm(elasticity_form, basis)
    tol = GEOM_TOL
    clamp_x, clamp_y, _ = facet_dofs(basis, lambda p: np.abs(p[0]) < tol)
    tip = mesh.facets_satisfying(lambda p: np.abs(p[0] - CANT_L) < tol,
                                 boundaries_only=True)
    ty = CANT_P / CANT_H  # MPa
    f = edge_load_quad2(basis, tip, ty)
    load_check = facet_basis_load_difference(mesh, elem, tip, ty, f)
    u0 = np.zeros(basis.N)
    D = np.unique(np.concatenate([clamp_x, clamp_y]))
    u, res = solve_linear(K, f, u0, D)
    r = K @ u - f  # reaction = force of the constraint on the body
    values = {
        "clamp_fx": float(r[clamp_x].sum()),
        "clamp_fy": float(r[clamp_y].sum()),
    }
    checks = {
        "applied_load_fy": float(f.sum()),
        "facetbasis_load_max_difference": load_check,
        "relative_residual": float(res),
    }
    for pt in CANT_DISP_POINTS:
        for q, v in point_quantities(basis, u, pt, ["ux", "uy"]).items():
            values[f"{q}@({pt[0]:g},{pt[1]:g})"] = v
    for pt in CANT_SXX_POINTS:
        for q, v in point_quantities(basis, u, pt, ["sigma_xx"]).items():
            values[f"{q}@({pt[0]:g},{pt[1]:g})"] = v
    for pt in CANT_SXY_POINTS:
        for q, v in point_quantities(basis, u, pt, ["sigma_xy"]).items():
            values[f"{q}@({pt[0]:g},{pt[1]:g})"] = v
    hmin, hmax = element_sizes(mesh)
    return {
        "level": level,
        "element": "ElementVector(ElementQuad2) (9-node biquadratic quads)",
        "elements": int(mesh.t.shape[1]),
        "dofs": int(basis.N),
        "h_min": hmin,
        "h_max": hmax,
        "grading_beta": beta,
        "seconds": round(time.time() - t0, 2),
        "checks": checks,
        "values": values,
    }


def beam_estimate():
    """Euler-Bernoulli + Timoshenko shear estimate of the tip deflection
    (plane strain: E' = E / (1 - nu^2); shear modulus G, coefficient 5/6)."""
    e_ps = E_MOD / (1.0 - NU ** 2)
    inertia = CANT_H ** 3 / 12.0
    area = CANT_H
    g = MU
    kappa = 5.0 / 6.0
    bending = CANT_P * CANT_L ** 3 / (3.0 * e_ps * inertia)
    shear = CANT_P * CANT_L / (kappa * g * area)
    return {"E_plane_strain": e_ps, "I": inertia, "bending": bending,
            "shear": shear, "total": bending + shear}


# ------------------------------------------------------- error estimation
def error_estimate(seq):
    """Error estimate of the last value of a sequence obtained by doubling
    the element count per segment each level.

    If the last three values converge monotonically (successive differences
    of equal sign, shrinking), the observed order p = log2(d1 / d2) gives the
    Richardson extrapolation q_ext = q3 + d2 / (2^p - 1), and the estimate is
    |q3 - q_ext|; otherwise the estimate is |d2| (difference to the previous
    level, marked 'difference').  The estimate is never smaller than the
    round-off floor 1e-12 * max|q|."""
    q = np.asarray(seq, dtype=float)
    out = {"diff_last": float(abs(q[-1] - q[-2])) if q.size > 1 else None}
    floor = 1e-12 * float(np.max(np.abs(q)))
    if q.size >= 3:
        d1, d2 = q[-2] - q[-3], q[-1] - q[-2]
        if d1 != 0.0 and d2 != 0.0 and d1 * d2 > 0 and abs(d2) < abs(d1):
            p = math.log2(d1 / d2)
            ext = q[-1] + d2 / (2.0 ** p - 1.0)
            out.update(method="richardson", observed_order=p,
                       extrapolated=float(ext),
                       abs_error=max(float(abs(ext - q[-1])), floor))
        else:
            out.update(method="difference", observed_order=None,
                       extrapolated=None,
                       abs_error=max(float(abs(d2)), floor))
    else:
        out.update(method="difference", observed_order=None,
                   extrapolated=None,
                   abs_error=max(out["diff_last"] or 0.0, floor))
    scale = abs(q[-1])
    out["rel_error"] = (float(out["abs_error"] / scale)
                        if scale > 1e3 * floor and scale > 0 else None)
    return out


def run_sequence(solver, levels, beta, name, zero_keys=()):
    runs = []
    for lv in levels:
        info = solver(lv, beta)
        print(f"  [{name}] level {lv}: {info['elements']} elements, "
              f"{info['dofs']} dofs, h = {info['h_min']:.3g} .. "
              f"{info['h_max']:.3g} mm, {info['seconds']} s", flush=True)
        runs.append(info)
    keys = list(runs[0]["values"].keys())
    est = {k: error_estimate([r["values"][k] for r in runs]) for k in keys}
    for k in zero_keys:
        # exactly zero (equilibrium or antisymmetry): the computed values are
        # round-off, a relative error means nothing
        est[k].update(rel_error=None, exact_value=0.0,
                      note="exactly zero by equilibrium or antisymmetry; "
                           "the values are round-off")
    return runs, est


# ---------------------------------------------------------------- output
def fmt(v):
    return f"{v:.10e}"


def write_history(path, header_lines, columns, values):
    with open(path, "w") as fh:
        for line in header_lines:
            fh.write(f"# {line}\n")
        fh.write("time," + ",".join(columns) + "\n")
        fh.write("1.0," + ",".join(fmt(values[c]) for c in columns) + "\n")


def write_points(path, header_lines, rows):
    with open(path, "w") as fh:
        for line in header_lines:
            fh.write(f"# {line}\n")
        fh.write("time,x,y,quantity,value\n")
        for (x, y, q, v) in rows:
            fh.write(f"1.0,{x:g},{y:g},{q},{fmt(v)}\n")


def point_rows(values):
    rows = []
    for key, v in values.items():
        if "@" not in key:
            continue
        q, pos = key.split("@")
        x, y = (float(s) for s in pos.strip("()").split(","))
        rows.append((x, y, q, v))
    return rows


def describe_errors(est, keys):
    parts = []
    for k in keys:
        e = est[k]
        if "exact_value" in e:
            parts.append(f"{k} exactly 0 (round-off {e['abs_error']:.1g})")
            continue
        rel = (f"{100 * e['rel_error']:.2g} %" if e["rel_error"] is not None
               else f"abs {e['abs_error']:.2g}")
        parts.append(f"{k} {rel} ({e['method']})")
    return parts


def print_table(name, runs, est):
    print(f"\n== {name}: convergence ==")
    levels = [r["level"] for r in runs]
    print(f"{'quantity':24s}" + "".join(f"{'L' + str(lv):>18s}" for lv in levels)
          + f"{'est. error':>12s} {'rel.':>9s} {'order':>6s}")
    for k in runs[0]["values"]:
        e = est[k]
        rel = f"{e['rel_error']:.1e}" if e["rel_error"] is not None else "-"
        if "exact_value" in e:
            rel = "(=0)"
        p = (f"{e['observed_order']:.2f}" if e["observed_order"] is not None
             else "-")
        print(f"{k:24s}" + "".join(f"{r['values'][k]:18.10e}" for r in runs)
              + f"{e['abs_error']:12.2e} {rel:>9s} {p:>6s}")


def markdown_table(runs, est):
    """The convergence table in Markdown (for the README)."""
    levels = [r["level"] for r in runs]
    lines = ["| level | elements | dofs | h_min (mm) | h_max (mm) | time (s) |",
             "|---|---|---|---|---|---|"]
    for r in runs:
        lines.append(f"| {r['level']} | {r['elements']} | {r['dofs']} | "
                     f"{r['h_min']:.3g} | {r['h_max']:.3g} | {r['seconds']} |")
    lines.append("")
    lines.append("| quantity | " + " | ".join(f"L{lv}" for lv in levels)
                 + " | est. error | rel. | order | method |")
    lines.append("|---" * (len(levels) + 5) + "|")
    for k in runs[0]["values"]:
        e = est[k]
        if "exact_value" in e:
            rel = "exactly 0"
        elif e["rel_error"] is not None:
            rel = f"{e['rel_error']:.1e}"
        else:
            rel = "-"
        p = (f"{e['observed_order']:.2f}" if e["observed_order"] is not None
             else "-")
        lines.append(f"| `{k}` | " + " | ".join(f"{r['values'][k]:.9e}"
                                                 for r in runs)
                     + f" | {e['abs_error']:.1e} | {rel} | {p} | {e['method']} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--out", default=None,
                    help="output directory (default tests/data/fem; with "
                         "--quick the system temp dir's fem-reference-quick, "
                         "so that a quick run never overwrites the "
                         "committed data by accident)")
    ap.add_argument("--quick", action="store_true",
                    help="cheap check: coarse levels only (seconds)")
    ap.add_argument("--ct-beta", type=float, default=CT_BETA,
                    help=f"CT grading exponent (default {CT_BETA:g})")
    ap.add_argument("--cantilever-beta", type=float, default=CANT_BETA,
                    help=f"cantilever grading exponent (default {CANT_BETA:g})")
    ap.add_argument("--markdown", metavar="FILE",
                    help="also write the convergence tables in Markdown to FILE")
    args = ap.parse_args(argv)

    if args.quick:
        ct_levels, cant_levels = [0, 1, 2], [0, 1, 2]
    else:
        ct_levels, cant_levels = CT_LEVELS, CANT_LEVELS
    if args.out is None:
        args.out = (os.path.join(tempfile.gettempdir(), "fem-reference-quick")
                    if args.quick else "tests/data/fem")
    os.makedirs(args.out, exist_ok=True)
    t_start = time.time()

    print("ct-elastic:", flush=True)
    ct_runs, ct_est = run_sequence(solve_ct, ct_levels, args.ct_beta,
                                   "ct-elastic", zero_keys=CT_ZERO)
    print("cantilever:", flush=True)
    ca_runs, ca_est = run_sequence(solve_cantilever, cant_levels,
                                   args.cantilever_beta, "cantilever",
                                   zero_keys=CANT_ZERO)
    print_table("ct-elastic", ct_runs, ct_est)
    print_table("cantilever", ca_runs, ca_est)

    beam = beam_estimate()
    tip_fem = ca_runs[-1]["values"]["uy@(100,5)"]
    print("\ncantilever tip deflection uy(100,5):")
    print(f"  FEM (finest)                    {tip_fem:.6e} mm")
    print(f"  Euler-Bernoulli (E' plane strain) {beam['bending']:.6e} mm")
    print(f"  + Timoshenko shear (k = 5/6)    {beam['shear']:.6e} mm")
    print(f"  beam theory total               {beam['total']:.6e} mm "
          f"(FEM / beam = {tip_fem / beam['total']:.5f})")

    versions = (f"scikit-fem {skfem.__version__}, numpy {np.__version__}, "
                f"scipy {scipy.__version__}, python {platform.python_version()}")
    elem_txt = "ElementVector(ElementQuad2), 9-node biquadratic quadrilaterals"

    # --- CT
    fin = ct_runs[-1]
    ct_common = [
        "ct-elastic: independent FEM reference (tools/fem_reference/reference.py)",
        "plane strain, small strain linear elastic, E = 36000 MPa, nu = 0.18, quasi-static, no body force",
        "units: mm, s, N, MPa; forces per mm thickness; positions in the reference configuration",
        "domain [0,200]x[0,200] minus notch [0,110]x[95,105]; load: y=95, 0<=x<=30, u_y=-0.01 mm, u_x free;"
        " support: y=105, 0<=x<=30, u_x=u_y=0",
        f"element: {elem_txt}; structured tensor mesh graded (power {args.ct_beta:g}) towards x=0,30,110 and y=95,105",
        f"finest mesh: level {fin['level']}, {fin['elements']} elements, {fin['dofs']} dofs, "
        f"h = {fin['h_min']:.3g} .. {fin['h_max']:.3g} mm",
        f"{versions}",
    ]
    write_history(
        os.path.join(args.out, "ct-elastic-history.csv"),
        ct_common + ["reaction = sum over the constrained dofs of the set of (K u)_i (force of the constraint on the body)",
                     "estimated discretisation error of the finest values: "
                     + "; ".join(describe_errors(ct_est, ["load_fy", "support_fx", "support_fy"]))],
        # support_fx is zero by equilibrium (its value is round-off): a relative error against it is
        # undefined, so the column is left out of the CSV (it is in convergence.json).
        ["load_fy", "support_fy"], fin["values"])
    write_points(
        os.path.join(args.out, "ct-elastic-points.csv"),
        ct_common + ["stresses: small-strain stress from the FE displacement gradient at the point,"
                     " averaged over the elements whose closure contains it",
                     "estimated errors per quantity: see convergence.json"],
        point_rows(fin["values"]))

    # --- cantilever
    fin = ca_runs[-1]
    ca_common = [
        "cantilever: independent FEM reference (tools/fem_reference/reference.py)",
        "plane strain, small strain linear elastic, E = 36000 MPa, nu = 0.18, quasi-static, no body force",
        "units: mm, s, N, MPa; forces per mm thickness; positions in the reference configuration",
        "domain [0,100]x[0,10]; clamp: x=0, u_x=u_y=0; tip: uniform traction t_y=-0.1 MPa on x=100 (P = -1 N/mm),"
        " consistent nodal loads",
        f"element: {elem_txt}; structured tensor mesh graded (power {args.cantilever_beta:g}) towards x=0,100 and y=0,10",
        f"finest mesh: level {fin['level']}, {fin['elements']} elements, {fin['dofs']} dofs, "
        f"h = {fin['h_min']:.3g} .. {fin['h_max']:.3g} mm",
        f"beam theory tip deflection: Euler-Bernoulli {beam['bending']:.6e} mm + Timoshenko shear "
        f"{beam['shear']:.6e} mm = {beam['total']:.6e} mm; FEM uy(100,5) = {tip_fem:.6e} mm",
        f"{versions}",
    ]
    write_history(
        os.path.join(args.out, "cantilever-history.csv"),
        ca_common + ["reaction = sum over the clamped dofs of (K u - f)_i (force of the constraint on the body)",
                     "estimated discretisation error of the finest values: "
                     + "; ".join(describe_errors(ca_est, ["clamp_fx", "clamp_fy"]))
                     + "; tip uy(100,5) " + describe_errors(ca_est, ["uy@(100,5)"])[0].split(" ", 1)[1]],
        # clamp_fx is zero by equilibrium: left out of the CSV like support_fx above.
        ["clamp_fy"], fin["values"])
    write_points(
        os.path.join(args.out, "cantilever-points.csv"),
        ca_common + ["stresses: small-strain stress from the FE displacement gradient at the point,"
                     " averaged over the elements whose closure contains it",
                     "estimated errors per quantity: see convergence.json"],
        point_rows(fin["values"]))

    def problem_json(runs, est, extra):
        # wall-clock times stay out of the file, which is then reproducible
        levels = [{k: v for k, v in r.items() if k != "seconds"}
                  for r in runs]
        return dict(extra, levels=levels, error_estimate=est,
                    committed="finest level values")

    conv = {
        "generator": "tools/fem_reference/reference.py"
                     + (" --quick" if args.quick else ""),
        "versions": versions,
        "units": "mm, s, N, MPa, t; plane strain; forces per mm thickness",
        "material": {"E": E_MOD, "nu": NU, "lambda": LAMBDA, "mu": MU},
        "error_estimate_method": error_estimate.__doc__.strip(),
        "ct-elastic": problem_json(ct_runs, ct_est, {
            "x_segments": CT_X_SEGMENTS, "y_segments": CT_Y_SEGMENTS,
            "segments_note": "(a, b, elements at level 0, graded at a, graded at b); "
                             "level k has 2^k times the elements",
            "load_uy": CT_LOAD_UY}),
        "cantilever": problem_json(ca_runs, ca_est, {
            "x_segments": CANT_X_SEGMENTS, "y_segments": CANT_Y_SEGMENTS,
            "segments_note": "(a, b, elements at level 0, graded at a, graded at b); "
                             "level k has 2^k times the elements",
            "load_resultant_fy": CANT_P,
            "beam_theory": beam}),
    }
    with open(os.path.join(args.out, "convergence.json"), "w") as fh:
        json.dump(conv, fh, indent=1, sort_keys=False)
        fh.write("\n")
    if args.markdown:
        with open(args.markdown, "w") as fh:
            fh.write("### ct-elastic\n\n" + markdown_table(ct_runs, ct_est)
                     + "\n### cantilever\n\n" + markdown_table(ca_runs, ca_est))
    print(f"\nwrote {args.out}/ct-elastic-history.csv, ct-elastic-points.csv, "
          f"cantilever-history.csv, cantilever-points.csv, convergence.json")
    print(f"total time {time.time() - t_start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
