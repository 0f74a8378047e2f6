//! Invariants of every interpolator: partition of unity, zero gradient sum, exact reproduction of linear
//! fields and their gradients, for random, edge, node, deformed and near-margin configurations.

use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector2, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use super::*;
use crate::geometry::Seeding;
use crate::particles::tests::rect_geometry;

const H: f64 = 0.5;
const N: usize = 2;
/// The corner hold (cell widths) the CPDI tests set besides plain CPDI.
const HOLD: f64 = 0.1;

/// 24 x 20 cells of h = 0.5 mm with the origin off zero.
fn grid() -> Grid {
    Grid::new(Vector2::new(-3.0, 1.0), H, [24, 20]).unwrap()
}

/// Points at `xs` (2^D per cell: volume `(h/2)^D`, half-edges `h/4`) whose domains are deformed by `f`
/// (`r_i = F r_i^0`, corners the parallelogram or parallelepiped).
fn points<const D: usize>(xs: &[SVector<f64, D>], f: SMatrix<f64, D, D>) -> Particles<D> {
    let mut ps = Particles::new();
    for &x in xs {
        ps.push(
            x,
            (H / 2.0).powi(D as i32),
            1.0,
            SMatrix::identity() * (H / 4.0),
            0,
        );
    }
    for p in 0..ps.len() {
        ps.set_deformation(p, f);
    }
    ps
}

/// Random points well inside the grid (3 cells of margin).
fn random_positions(rng: &mut StdRng, n: usize) -> Vec<Vector2<f64>> {
    let g = grid();
    let (lo, hi) = (
        g.origin() + Vector2::repeat(3.0 * H),
        g.upper() - Vector2::repeat(3.0 * H),
    );
    (0..n)
        .map(|_| Vector2::new(rng.random_range(lo.x..hi.x), rng.random_range(lo.y..hi.y)))
        .collect()
}

/// Positions exactly on nodes, on vertical and on horizontal cell edges.
fn edge_and_node_positions(rng: &mut StdRng) -> Vec<Vector2<f64>> {
    let g = grid();
    let mut xs = Vec::new();
    for i in 4..20 {
        for j in [4, 9, 16] {
            let node = g.node_position(g.node_index(i, j));
            xs.push(node);
            xs.push(node + Vector2::new(rng.random_range(0.0..H), 0.0));
            xs.push(node + Vector2::new(0.0, rng.random_range(0.0..H)));
        }
    }
    xs
}

/// The deformation gradients of the CPDI domain tests: none, stretch, shear, general, and a stretch to a
/// domain 3 cells long (the CPDI merge's fallback path).
fn deformations() -> [Matrix2<f64>; 5] {
    [
        Matrix2::identity(),
        Matrix2::new(6.0, 0.0, 0.0, 1.0),
        Matrix2::new(2.5, 0.0, 0.0, 0.5),
        Matrix2::new(1.0, 1.5, 0.0, 1.0),
        Matrix2::new(1.6, 0.4, -0.3, 0.8),
    ]
}

/// Checks the invariants at every point, for CPDI both plain and with the corner hold [`HOLD`];
/// `centre[p]` is the point the linear field must reproduce.
fn check_invariants<const D: usize>(
    kind: ShapeKind,
    g: &Grid<D>,
    ps: &Particles<D>,
    centre: &[SVector<f64, D>],
) {
    for hold in [0.0, HOLD] {
        let mut table = ShapeTable::new();
        table.set_corner_hold(hold);
        check_table_invariants(kind, g, ps, centre, &mut table);
    }
}

fn check_table_invariants<const D: usize>(
    kind: ShapeKind,
    g: &Grid<D>,
    ps: &Particles<D>,
    centre: &[SVector<f64, D>],
    table: &mut ShapeTable<D>,
) {
    let hold = table.corner_hold();
    table
        .compute(kind, g, ps)
        .unwrap_or_else(|e| panic!("{kind:?}: {e}"));
    assert_eq!(table.len(), ps.len());
    assert_eq!(table.kind(), Some(kind));
    for (p, ws) in table.iter() {
        assert!(!ws.is_empty() && ws.len() <= kind.max_support::<D>());
        let mut nodes: Vec<u32> = ws.iter().map(|w| w.node).collect();
        nodes.sort_unstable();
        nodes.dedup();
        assert_eq!(nodes.len(), ws.len(), "{kind:?} point {p}: duplicate nodes");
        let sum: f64 = ws.iter().map(|w| w.value).sum();
        let grad_sum: SVector<f64, D> = ws.iter().map(|w| w.grad).sum();
        let x: SVector<f64, D> = ws
            .iter()
            .map(|w| w.value * g.node_position(w.node as usize))
            .sum();
        let grad_x: SMatrix<f64, D, D> = ws
            .iter()
            .map(|w| g.node_position(w.node as usize) * w.grad.transpose())
            .sum();
        assert!(
            (sum - 1.0).abs() < 1e-13,
            "{kind:?} point {p}: sum S = {sum}"
        );
        assert!(
            grad_sum.norm() < 1e-12,
            "{kind:?} point {p}: sum grad S = {grad_sum}"
        );
        assert!(
            (x - centre[p]).norm() < 1e-12,
            "{kind:?} point {p}: sum S x_I = {x}, expected {}",
            centre[p]
        );
        assert!(
            (grad_x - SMatrix::<f64, D, D>::identity()).norm() < 1e-12,
            "{kind:?} point {p}: grad x = {grad_x}"
        );
        // CPDI's held corners weigh a node along an axis by -hold at least and by 1 + hold at most: down
        // to -hold (1 + hold)^(D - 1) at a corner, never below it for the point.
        let floor = match kind {
            ShapeKind::Cpdi1 | ShapeKind::Cpdi2 => -hold * (1.0 + hold).powi(D as i32 - 1),
            _ => 0.0,
        };
        assert!(
            ws.iter().all(|w| w.value >= floor - 1e-15),
            "{kind:?} point {p}: a weight below {floor}"
        );
    }
}

/// [`check_invariants`] of every interpolator for points at `xs` with domains deformed by `f`.
fn check_every_kind(xs: &[Vector2<f64>], f: Matrix2<f64>) {
    let ps = points(xs, f);
    for kind in ShapeKind::ALL {
        check_invariants(kind, &grid(), &ps, xs);
    }
}

#[test]
fn shape_invariants_random_positions() {
    let mut rng = StdRng::seed_from_u64(1);
    let xs = random_positions(&mut rng, 500);
    check_every_kind(&xs, Matrix2::identity());
}

#[test]
fn shape_invariants_on_cell_edges_and_nodes() {
    let mut rng = StdRng::seed_from_u64(2);
    let xs = edge_and_node_positions(&mut rng);
    check_every_kind(&xs, Matrix2::identity());
}

#[test]
fn shape_invariants_in_stretched_and_sheared_domains() {
    let mut rng = StdRng::seed_from_u64(3);
    let mut xs = random_positions(&mut rng, 200);
    xs.extend(edge_and_node_positions(&mut rng));
    for f in deformations() {
        check_every_kind(&xs, f);
    }
}

/// Area centroid of a simple polygon (mm).
fn centroid(c: &[Vector2<f64>]) -> Vector2<f64> {
    let (mut a, mut m) = (0.0, Vector2::zeros());
    for k in 0..4 {
        let cross = c[k].perp(&c[(k + 1) % 4]);
        a += 0.5 * cross;
        m += (c[k] + c[(k + 1) % 4]) * cross / 6.0;
    }
    m / a
}

#[test]
fn shape_cpdi2_general_quadrilaterals_reproduce_the_centroid() {
    let mut rng = StdRng::seed_from_u64(4);
    let xs = random_positions(&mut rng, 300);
    let mut ps = points(&xs, Matrix2::identity());
    // Perturb each corner by up to 0.3 of the half-edge: convex, counter-clockwise, not a parallelogram.
    for c in ps.corners.iter_mut() {
        *c += Vector2::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3)) * (H / 4.0);
    }
    let centres: Vec<_> = ps.corners.chunks(4).map(centroid).collect();
    check_invariants(ShapeKind::Cpdi2, &grid(), &ps, &centres);
}

#[test]
fn shape_cpdi2_equals_cpdi1_on_parallelograms() {
    let mut rng = StdRng::seed_from_u64(5);
    let xs = random_positions(&mut rng, 200);
    for f in deformations() {
        assert_cpdi2_equals_cpdi1(&grid(), &points(&xs, f), 1e-14, 1e-12);
    }
}

/// Asserts that CPDI2 and CPDI1 give the points `ps` the same nodes, weights (to `value_tol`) and
/// gradients (to `grad_tol`).
fn assert_cpdi2_equals_cpdi1<const D: usize>(
    grid: &Grid<D>,
    ps: &Particles<D>,
    value_tol: f64,
    grad_tol: f64,
) {
    let (mut t1, mut t2) = (ShapeTable::new(), ShapeTable::new());
    t1.compute(ShapeKind::Cpdi1, grid, ps).unwrap();
    t2.compute(ShapeKind::Cpdi2, grid, ps).unwrap();
    for p in 0..ps.len() {
        let (w1, w2) = (t1.weights(p), t2.weights(p));
        assert_eq!(w1.len(), w2.len());
        for (a, b) in w1.iter().zip(w2) {
            assert_eq!(a.node, b.node);
            assert!((a.value - b.value).abs() < value_tol);
            assert!((a.grad - b.grad).norm() < grad_tol);
        }
    }
}

/// For each kind, the smallest distance (cell units) from the grid border at which the support still fits.
fn touching_distance(kind: ShapeKind) -> f64 {
    match kind {
        ShapeKind::Linear => 0.0,
        ShapeKind::Gimp | ShapeKind::Cpdi1 | ShapeKind::Cpdi2 => 0.25,
        ShapeKind::Bspline2 => 0.5,
    }
}

#[test]
fn shape_invariants_next_to_the_grid_border_and_out_of_grid_errors() {
    let g = grid();
    let (lo, hi) = (g.origin(), g.upper());
    for kind in ShapeKind::ALL {
        let d = touching_distance(kind) * H;
        let xs = vec![
            lo + Vector2::repeat(d),
            hi - Vector2::repeat(d),
            Vector2::new(lo.x + d, 0.5 * (lo.y + hi.y)),
            Vector2::new(0.5 * (lo.x + hi.x), hi.y - d),
        ];
        check_invariants(kind, &g, &points(&xs, Matrix2::identity()), &xs);
        // Slightly further out: the support (or the point) leaves the grid. The error names the first
        // offending point deterministically.
        let mut out = xs.clone();
        out.insert(0, Vector2::new(0.0, 5.0));
        out[2] += Vector2::new(0.0, 1e-6);
        out[4] += Vector2::new(0.0, 1e-6);
        let mut table = ShapeTable::new();
        let err = table
            .compute(kind, &g, &points(&out, Matrix2::identity()))
            .unwrap_err();
        match err {
            ShapeError::Grid(GridError::OutsideGrid {
                particle,
                locus,
                x,
                y,
                z: None,
            }) => {
                assert_eq!(particle, 2, "{kind:?}");
                if locus == Locus::Centre {
                    assert_eq!((x, y), (out[2].x, out[2].y));
                }
            }
            other => panic!("{kind:?}: unexpected {other}"),
        }
        assert!(table.is_empty() && table.kind().is_none());
        assert!(err.to_string().contains("material point 2"), "{err}");
    }
}

#[test]
fn shape_cpdi_corner_error_names_the_corner() {
    let g = grid();
    let x = g.origin() + Vector2::new(0.1, 3.0);
    let mut table = ShapeTable::new();
    let err = table
        .compute(ShapeKind::Cpdi1, &g, &points(&[x], Matrix2::identity()))
        .unwrap_err();
    assert!(matches!(
        err,
        ShapeError::Grid(GridError::OutsideGrid {
            particle: 0,
            locus: Locus::Corner(0),
            ..
        })
    ));
    assert!(err.to_string().contains("CPDI corner 1"), "{err}");
}

#[test]
fn shape_degenerate_domains_and_gimp_width_are_errors() {
    let g = grid();
    let x = Vector2::new(1.0, 4.0);
    let mut table = ShapeTable::new();
    for f in [
        Matrix2::new(1.0, 0.0, 0.0, 0.0),
        Matrix2::new(-1.0, 0.0, 0.0, 1.0),
    ] {
        for kind in [ShapeKind::Cpdi1, ShapeKind::Cpdi2] {
            let err = table.compute(kind, &g, &points(&[x], f)).unwrap_err();
            assert!(
                matches!(err, ShapeError::DegenerateDomain { particle: 0, .. }),
                "{err}"
            );
        }
    }
    let mut ps = points(&[x], Matrix2::identity());
    ps.r0[0].set_column(0, &Vector2::new(0.6 * H, 0.0));
    let err = table.compute(ShapeKind::Gimp, &g, &ps).unwrap_err();
    assert!(
        matches!(err, ShapeError::GimpWidth { particle: 0, .. }),
        "{err}"
    );
}

/// N x N points per cell seeded in the rectangle from `min` to `max` (mm).
fn seeded(min: [f64; 2], max: [f64; 2]) -> Particles {
    Particles::seed(
        &rect_geometry(min, max),
        &Seeding {
            h: H,
            points_per_cell: N,
            density: 1.0,
            body: 0,
        },
    )
    .unwrap()
}

#[test]
fn shape_undeformed_seeded_points_have_compact_supports() {
    // 2 x 2 points per cell: CPDI corners and GIMP support edges lie on grid lines, so only the owning cell's
    // 4 nodes carry weight; linear always lists 4 nodes; the B-spline reaches 3 x 3 nodes.
    let ps = seeded([0.0, 3.0], [4.0, 6.0]);
    let mut table = ShapeTable::new();
    for kind in ShapeKind::ALL {
        assert_compact_supports(kind, &mut table, &grid(), &ps);
        check_invariants(kind, &grid(), &ps, &ps.x);
    }
}

/// The supports of undeformed points whose domains lie on grid lines: the `2^D` nodes of the owning
/// cell for every interpolator but the quadratic B-spline, which reaches `3^D` nodes.
fn assert_compact_supports<const D: usize>(
    kind: ShapeKind,
    table: &mut ShapeTable<D>,
    grid: &Grid<D>,
    ps: &Particles<D>,
) {
    table.compute(kind, grid, ps).unwrap();
    let expected = match kind {
        ShapeKind::Bspline2 => 3_usize.pow(D as u32),
        _ => 1 << D,
    };
    assert!(table.iter().all(|(_, ws)| ws.len() == expected), "{kind:?}");
}

#[test]
fn shape_table_is_reused_without_reallocation() {
    let mut rng = StdRng::seed_from_u64(6);
    let xs = random_positions(&mut rng, 1000);
    let ps = points(&xs, Matrix2::new(1.1, 0.2, 0.0, 0.9));
    let mut table = ShapeTable::new();
    table.compute(ShapeKind::Cpdi1, &grid(), &ps).unwrap();
    let (pw, pc) = (table.weights.as_ptr(), table.counts.as_ptr());
    for kind in ShapeKind::ALL {
        table.compute(kind, &grid(), &ps).unwrap();
        assert_eq!(table.stride(), kind.max_support::<2>());
        assert_eq!(
            (table.weights.as_ptr(), table.counts.as_ptr()),
            (pw, pc),
            "{kind:?}"
        );
    }
}

#[test]
fn shape_kind_config_names() {
    #[derive(Deserialize)]
    struct Config {
        kind: ShapeKind,
    }
    for kind in ShapeKind::ALL {
        let c: Config = toml::from_str(&format!("kind = \"{}\"", kind.name())).unwrap();
        assert_eq!(c.kind, kind);
    }
    assert!(toml::from_str::<Config>("kind = \"CPDI\"").is_err());
}

// ---- 3D ----

/// 14 x 12 x 10 cells of h = 0.5 mm with the origin off zero.
fn grid3() -> Grid<3> {
    Grid::new(Vector3::new(-1.0, 0.5, 2.0), H, [14, 12, 10]).unwrap()
}

/// Random points 3 cells inside the 3D grid, and points on its nodes, edges and faces.
fn positions3(rng: &mut StdRng, n: usize) -> Vec<Vector3<f64>> {
    let g = grid3();
    let (lo, hi) = (
        g.origin() + Vector3::repeat(3.0 * H),
        g.upper() - Vector3::repeat(3.0 * H),
    );
    let mut xs: Vec<Vector3<f64>> = (0..n)
        .map(|_| Vector3::from_fn(|d, _| rng.random_range(lo[d]..hi[d])))
        .collect();
    for ijk in [[4, 4, 4], [5, 7, 6], [9, 5, 4]] {
        let node = g.node_position(g.node_at(ijk));
        xs.push(node);
        for d in 0..3 {
            let mut along = Vector3::zeros();
            along[d] = rng.random_range(0.0..H);
            xs.push(node + along);
            xs.push(node + Vector3::repeat(rng.random_range(0.0..H)) - along);
        }
    }
    xs
}

/// None, a stretch to a domain 3 cells long (the merge's fallback path), a shear and a general `F`.
fn deformations3() -> [Matrix3<f64>; 4] {
    [
        Matrix3::identity(),
        Matrix3::new(6.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        Matrix3::new(1.0, 1.5, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        Matrix3::new(1.3, 0.2, -0.1, 0.1, 0.8, 0.3, -0.2, 0.1, 1.1),
    ]
}

#[test]
fn shape_3d_invariants_in_undeformed_and_deformed_domains() {
    let mut rng = StdRng::seed_from_u64(31);
    let xs = positions3(&mut rng, 150);
    for f in deformations3() {
        let ps = points(&xs, f);
        for kind in ShapeKind::ALL {
            check_invariants(kind, &grid3(), &ps, &xs);
        }
    }
}

/// Volume centroid of the trilinear hexahedron with `corners` (lattice order), by the 3-point Gauss rule
/// (exact: the integrands are at most cubic per direction).
fn hexahedron_centroid(corners: &[Vector3<f64>]) -> Vector3<f64> {
    let q = 0.6_f64.sqrt();
    let rule = [(-q, 5.0 / 9.0), (0.0, 8.0 / 9.0), (q, 5.0 / 9.0)];
    let (mut vol, mut moment) = (0.0, Vector3::zeros());
    for &(a, wa) in &rule {
        for &(b, wb) in &rule {
            for &(c, wc) in &rule {
                let xi = [a, b, c];
                let mut x = Vector3::zeros();
                let mut jac = Matrix3::zeros();
                for (k, xc) in corners.iter().enumerate() {
                    let s: [f64; 3] =
                        std::array::from_fn(|d| if (k >> d) & 1 == 1 { 1.0 } else { -1.0 });
                    let f: [f64; 3] = std::array::from_fn(|d| 0.5 * (1.0 + s[d] * xi[d]));
                    x += xc * f[0] * f[1] * f[2];
                    let dm = Vector3::new(
                        0.5 * s[0] * f[1] * f[2],
                        0.5 * s[1] * f[0] * f[2],
                        0.5 * s[2] * f[0] * f[1],
                    );
                    jac += xc * dm.transpose();
                }
                let w = wa * wb * wc * jac.determinant();
                vol += w;
                moment += x * w;
            }
        }
    }
    moment / vol
}

#[test]
fn shape_3d_cpdi2_general_hexahedra_reproduce_the_centroid_and_equal_cpdi1_on_parallelepipeds() {
    let mut rng = StdRng::seed_from_u64(32);
    let xs = positions3(&mut rng, 120);
    let mut ps = points(&xs, deformations3()[3]);
    // CPDI2 on parallelepipeds is CPDI1.
    assert_cpdi2_equals_cpdi1(&grid3(), &ps, 1e-13, 1e-11);
    // Perturbed corners: general hexahedra with curved faces.
    for c in ps.corners.iter_mut() {
        *c += Vector3::from_fn(|_, _| rng.random_range(-0.25..0.25)) * (H / 4.0);
    }
    let centres: Vec<_> = ps.corners.chunks(8).map(hexahedron_centroid).collect();
    check_invariants(ShapeKind::Cpdi2, &grid3(), &ps, &centres);
    // An inverted hexahedron is an error naming the point.
    let mut bad = points(&xs[..3], Matrix3::identity());
    bad.corners_mut(1).swap(0, 7);
    bad.corners_mut(1).swap(1, 6);
    bad.corners_mut(1).swap(2, 5);
    bad.corners_mut(1).swap(3, 4);
    let err = ShapeTable::new()
        .compute(ShapeKind::Cpdi2, &grid3(), &bad)
        .unwrap_err();
    assert!(
        matches!(err, ShapeError::DegenerateDomain { particle: 1, .. }),
        "{err}"
    );
}

#[test]
fn shape_3d_seeded_supports_and_out_of_grid_errors() {
    let g = grid3();
    let xs: Vec<Vector3<f64>> = crate::particles::lattice([4, 3, 2])
        .map(|c| g.origin() + Vector3::from_fn(|d, _| (3.0 + c[d] as f64 + 0.25) * H))
        .collect();
    let ps = points(&xs, Matrix3::identity());
    let mut table = ShapeTable::new();
    for kind in ShapeKind::ALL {
        assert_compact_supports(kind, &mut table, &g, &ps);
        assert_eq!(table.stride(), kind.max_support::<3>());
    }
    let out = points(
        &[g.upper() - Vector3::new(1.0, 1.0, 0.1 * H)],
        Matrix3::identity(),
    );
    for kind in [ShapeKind::Cpdi1, ShapeKind::Bspline2] {
        let err = table.compute(kind, &g, &out).unwrap_err();
        assert!(
            matches!(
                err,
                ShapeError::Grid(GridError::OutsideGrid { z: Some(_), .. })
            ),
            "{kind:?}: {err}"
        );
    }
}

/// The CPDI1 table of `ps` on `grid()` with the corner hold `hold`.
fn cpdi1_table(ps: &Particles<2>, hold: f64) -> ShapeTable<2> {
    let mut table = ShapeTable::new();
    table.set_corner_hold(hold);
    table.compute(ShapeKind::Cpdi1, &grid(), ps).unwrap();
    table
}

#[test]
fn shape_cpdi_corners_that_cross_a_line_by_a_sliver_add_no_node() {
    // Seeded points (domains on grid lines) moved by 0.03 cell: with the hold every point keeps the 4 nodes
    // of its cell; without it the corners that crossed a line reach the next cells' nodes (9 nodes).
    let g = grid();
    let corner = g.node_position(g.node_index(6, 6));
    let xs: Vec<Vector2<f64>> = (0..4)
        .flat_map(|i| (0..4).map(move |j| Vector2::new(i as f64 + 0.5, j as f64 + 0.5)))
        .map(|ij| corner + ij * (H / 2.0) + Vector2::new(-0.03, -0.02) * H)
        .collect();
    let ps = points(&xs, Matrix2::identity());
    let held = cpdi1_table(&ps, HOLD);
    let plain = cpdi1_table(&ps, 0.0);
    assert!(held.iter().all(|(_, ws)| ws.len() == 4));
    assert!(held.iter().all(|(_, ws)| ws.iter().all(|w| w.value >= 0.0)));
    assert_eq!(plain.iter().filter(|(_, ws)| ws.len() == 9).count(), 4);
    check_invariants(ShapeKind::Cpdi1, &g, &ps, &xs);
    // Crossed by rounding only: no node across the line either.
    let xs: Vec<Vector2<f64>> = xs
        .iter()
        .map(|x| x - Vector2::new(-0.03, -0.02) * H - Vector2::repeat(1e-15))
        .collect();
    let rounded = cpdi1_table(&points(&xs, Matrix2::identity()), HOLD);
    assert!(rounded.iter().all(|(_, ws)| ws.len() == 4));
}

#[test]
fn shape_cpdi_held_corners_of_wide_domains_fit_the_support() {
    // Domains stretched over 2.3 and 4.8 cells whose corners sit in the blend: the held corners' third
    // node per axis must not overflow the 4^D support; such domains take plain CPDI's merge.
    let g = grid();
    for (half, hold) in [
        (Vector2::new(1.15, 0.65), HOLD),
        (Vector2::new(2.4, 0.9), 0.25),
    ] {
        let x = g.origin() + Vector2::new(10.0, 10.5) * H;
        let mut ps = points(&[x], Matrix2::identity());
        ps.r0[0] = Matrix2::from_diagonal(&(half * H));
        ps.set_deformation(0, Matrix2::identity());
        let mut table = ShapeTable::new();
        table.set_corner_hold(hold);
        check_table_invariants(ShapeKind::Cpdi1, &g, &ps, &[x], &mut table);
    }
}

#[test]
fn shape_cpdi_held_corners_values_are_closer_to_the_domain_integral() {
    // An axis-aligned quarter-cell domain whose left edge crossed a vertical line by eps: the exact
    // `S_Ip = (1/V) int N_I` is `eps^2`-close to the held corners' values and `eps`-close to plain CPDI's
    // (at the bodies' edges the forces move by eps:
    // `shape_cpdi_hold_keeps_the_patch_test_inside_and_moves_the_edge_forces_by_the_sliver`).
    let g = grid();
    let line = g.node_position(g.node_index(8, 5));
    // int_{-inf}^{t} of the 1D hat centred at 0.
    let hat_integral = |t: f64| match t {
        t if t <= -1.0 => 0.0,
        t if t <= 0.0 => 0.5 * (t + 1.0).powi(2),
        t if t <= 1.0 => 1.0 - 0.5 * (1.0 - t).powi(2),
        _ => 1.0,
    };
    for eps in [0.01, 0.05, 0.1, 0.15] {
        let x = line + Vector2::new(0.25 - eps, 0.25) * H;
        let ps = points(&[x], Matrix2::identity());
        let error = |hold: f64| {
            let table = cpdi1_table(&ps, hold);
            let mut worst: f64 = 0.0;
            for i in 6..11 {
                for j in 4..8 {
                    let node = g.node_index(i, j);
                    let s = (g.node_position(node) - x) / H;
                    // The domain is [-1/4, 1/4]^2 cells around x; the hat is a product of 1D hats.
                    let exact: f64 = (0..2)
                        .map(|d| (hat_integral(0.25 - s[d]) - hat_integral(-0.25 - s[d])) / 0.5)
                        .product();
                    let value = table
                        .weights(0)
                        .iter()
                        .find(|w| w.node as usize == node)
                        .map_or(0.0, |w| w.value);
                    worst = worst.max((value - exact).abs());
                }
            }
            worst
        };
        let (held, plain) = (error(HOLD), error(0.0));
        assert!(held < 0.5 * plain, "eps {eps}: held {held}, plain {plain}");
        assert!(held <= 2.0 * eps * eps, "eps {eps}: held {held}");
    }
}

#[test]
fn shape_cpdi_weights_are_continuous_as_a_point_crosses_a_line() {
    // A sheared domain moved across a vertical line in steps of 1e-4 cell: the hold, its blend and the plain
    // hats beyond it join without a jump in any value or gradient.
    let g = grid();
    let start = g.node_position(g.node_index(8, 5)) + Vector2::new(0.3, 0.4) * H;
    let f = Matrix2::new(1.1, 0.3, -0.1, 0.9);
    let step = 1e-4;
    let mut last: Option<Vec<Weight<2>>> = None;
    for k in 0..=6000 {
        let x = start - Vector2::new(k as f64 * step * H, 0.0);
        let ps = points(&[x], f);
        let now = cpdi1_table(&ps, HOLD).weights(0).to_vec();
        if let Some(before) = &last {
            let at = |ws: &[Weight<2>], node: u32| {
                ws.iter()
                    .find(|w| w.node == node)
                    .map_or((0.0, Vector2::zeros()), |w| (w.value, w.grad))
            };
            for node in before.iter().chain(&now).map(|w| w.node) {
                let ((v0, g0), (v1, g1)) = (at(before, node), at(&now, node));
                // Smooth changes are O(step) (values) and O(step / h) (gradients): 20x that is a jump.
                assert!(
                    (v1 - v0).abs() < 20.0 * step,
                    "k {k}, node {node}: {v0} -> {v1}"
                );
                assert!(
                    (g1 - g0).norm() < 20.0 * step / H * 10.0,
                    "k {k}, node {node}: {g0} -> {g1}"
                );
            }
        }
        last = Some(now);
    }
}

#[test]
fn shape_cpdi_hold_keeps_the_patch_test_inside_and_moves_the_edge_forces_by_the_sliver() {
    // Seeded points translated by eps: a uniform stress gives node I the force
    // `sigma . sum_p V_p grad S_Ip`. Inside the body it vanishes, plain or held (the held corners of the
    // lines around a node cancel); at the body's edges the hold moves it by the order of eps h (a held
    // edge corner puts `-eps` on the node inside instead of `eps` on the node outside).
    let seeded = seeded([-1.0, 3.0], [4.0, 8.0]);
    let g = grid();
    let eps = 0.05;
    let shift = Vector2::new(eps, 0.5 * eps) * H;
    let xs: Vec<Vector2<f64>> = seeded.x.iter().map(|x| x + shift).collect();
    let ps = points(&xs, Matrix2::identity());
    let sums = |hold: f64| {
        let table = cpdi1_table(&ps, hold);
        let mut sum = vec![Vector2::zeros(); g.num_nodes()];
        for (p, ws) in table.iter() {
            for w in ws {
                sum[w.node as usize] += ps.vol[p] * w.grad;
            }
        }
        sum
    };
    let (plain, held) = (sums(0.0), sums(HOLD));
    // Nodes at least two cells inside the body.
    let inside = |i: usize| {
        let x = g.node_position(i);
        x.x >= 0.0 && x.x <= 3.0 && x.y >= 4.0 && x.y <= 7.0
    };
    let nodes = 0..g.num_nodes();
    let worst = |f: &dyn Fn(usize) -> f64| nodes.clone().map(f).fold(0.0, f64::max);
    assert!(worst(&|i| if inside(i) { plain[i].norm() } else { 0.0 }) < 1e-12);
    assert!(worst(&|i| if inside(i) { held[i].norm() } else { 0.0 }) < 1e-12);
    let edge = worst(&|i| (held[i] - plain[i]).norm());
    assert!(
        edge > 0.1 * eps * H && edge < 4.0 * eps * H,
        "edge {edge} against eps h = {}",
        eps * H
    );
}
