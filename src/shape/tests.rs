//! Invariants of every interpolator: partition of unity, zero gradient sum, exact reproduction of linear
//! fields and their gradients, for random, edge, node, deformed and near-margin configurations.

use nalgebra::{Matrix2, Vector2};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use super::*;
use crate::particles::{Geometry, Region, Seeding, parallelogram_corners};

const H: f64 = 0.5;
const N: usize = 2;

/// 24 x 20 cells of h = 0.5 mm with the origin off zero.
fn grid() -> Grid {
    Grid::new(Vector2::new(-3.0, 1.0), H, 24, 20).unwrap()
}

/// Undeformed half-edges for 2 x 2 points per cell.
fn r0() -> (Vector2<f64>, Vector2<f64>) {
    (Vector2::new(H / 4.0, 0.0), Vector2::new(0.0, H / 4.0))
}

/// Points at `xs` whose domains are deformed by `f` (`r_i = F r_i^0`, corners the parallelogram).
fn points(xs: &[Vector2<f64>], f: Matrix2<f64>) -> Particles {
    let (r1_0, r2_0) = r0();
    let mut ps = Particles::new();
    for &x in xs {
        ps.push(x, H * H / 4.0, 1.0, r1_0, r2_0, 0);
    }
    for p in 0..ps.len() {
        ps.f[p] = f;
        ps.r1[p] = f * r1_0;
        ps.r2[p] = f * r2_0;
        ps.corners[p] = parallelogram_corners(ps.x[p], ps.r1[p], ps.r2[p]);
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

/// Checks the invariants at every point; `centre[p]` is the point the linear field must reproduce.
fn check_invariants(kind: ShapeKind, g: &Grid, ps: &Particles, centre: &[Vector2<f64>]) {
    let mut table = ShapeTable::new();
    table
        .compute(kind, g, ps)
        .unwrap_or_else(|e| panic!("{kind:?}: {e}"));
    assert_eq!(table.len(), ps.len());
    assert_eq!(table.kind(), Some(kind));
    for (p, ws) in table.iter() {
        assert!(!ws.is_empty() && ws.len() <= kind.max_support());
        let mut nodes: Vec<u32> = ws.iter().map(|w| w.node).collect();
        nodes.sort_unstable();
        nodes.dedup();
        assert_eq!(nodes.len(), ws.len(), "{kind:?} point {p}: duplicate nodes");
        let sum: f64 = ws.iter().map(|w| w.value).sum();
        let grad_sum: Vector2<f64> = ws.iter().map(|w| w.grad).sum();
        let x: Vector2<f64> = ws
            .iter()
            .map(|w| w.value * g.node_position(w.node as usize))
            .sum();
        let grad_x: Matrix2<f64> = ws
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
            (grad_x - Matrix2::identity()).norm() < 1e-12,
            "{kind:?} point {p}: grad x = {grad_x}"
        );
        assert!(ws.iter().all(|w| w.value >= -1e-15));
    }
}

#[test]
fn shape_invariants_random_positions() {
    let mut rng = StdRng::seed_from_u64(1);
    let xs = random_positions(&mut rng, 500);
    let ps = points(&xs, Matrix2::identity());
    for kind in ShapeKind::ALL {
        check_invariants(kind, &grid(), &ps, &xs);
    }
}

#[test]
fn shape_invariants_on_cell_edges_and_nodes() {
    let mut rng = StdRng::seed_from_u64(2);
    let xs = edge_and_node_positions(&mut rng);
    let ps = points(&xs, Matrix2::identity());
    for kind in ShapeKind::ALL {
        check_invariants(kind, &grid(), &ps, &xs);
    }
}

#[test]
fn shape_invariants_in_stretched_and_sheared_domains() {
    let mut rng = StdRng::seed_from_u64(3);
    let mut xs = random_positions(&mut rng, 200);
    xs.extend(edge_and_node_positions(&mut rng));
    for f in deformations() {
        let ps = points(&xs, f);
        for kind in ShapeKind::ALL {
            check_invariants(kind, &grid(), &ps, &xs);
        }
    }
}

/// Area centroid of a simple polygon (mm).
fn centroid(c: &[Vector2<f64>; 4]) -> Vector2<f64> {
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
    for corners in ps.corners.iter_mut() {
        // Perturb each corner by up to 0.3 of the half-edge: convex, counter-clockwise, not a parallelogram.
        for c in corners.iter_mut() {
            *c +=
                Vector2::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3)) * (H / 4.0);
        }
    }
    let centres: Vec<_> = ps.corners.iter().map(centroid).collect();
    check_invariants(ShapeKind::Cpdi2, &grid(), &ps, &centres);
}

#[test]
fn shape_cpdi2_equals_cpdi1_on_parallelograms() {
    let mut rng = StdRng::seed_from_u64(5);
    let xs = random_positions(&mut rng, 200);
    for f in deformations() {
        let ps = points(&xs, f);
        let (mut t1, mut t2) = (ShapeTable::new(), ShapeTable::new());
        t1.compute(ShapeKind::Cpdi1, &grid(), &ps).unwrap();
        t2.compute(ShapeKind::Cpdi2, &grid(), &ps).unwrap();
        for p in 0..ps.len() {
            let (w1, w2) = (t1.weights(p), t2.weights(p));
            assert_eq!(w1.len(), w2.len());
            for (a, b) in w1.iter().zip(w2) {
                assert_eq!(a.node, b.node);
                assert!((a.value - b.value).abs() < 1e-14);
                assert!((a.grad - b.grad).norm() < 1e-12);
            }
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
    ps.r1_0[0] = Vector2::new(0.6 * H, 0.0);
    let err = table.compute(ShapeKind::Gimp, &g, &ps).unwrap_err();
    assert!(
        matches!(err, ShapeError::GimpWidth { particle: 0, .. }),
        "{err}"
    );
}

#[test]
fn shape_undeformed_seeded_points_have_compact_supports() {
    // 2 x 2 points per cell: CPDI corners and GIMP support edges lie on grid lines, so only the owning cell's
    // 4 nodes carry weight; linear always lists 4 nodes; the B-spline reaches 3 x 3 nodes.
    let geometry = Geometry {
        include: vec![Region::Rect {
            min: [0.0, 3.0],
            max: [4.0, 6.0],
        }],
        exclude: vec![],
    };
    let ps = Particles::seed(
        &geometry,
        &Seeding {
            h: H,
            points_per_cell: N,
            density: 1.0,
            body: 0,
        },
    )
    .unwrap();
    let mut table = ShapeTable::new();
    for (kind, expected) in [
        (ShapeKind::Linear, 4),
        (ShapeKind::Gimp, 4),
        (ShapeKind::Cpdi1, 4),
        (ShapeKind::Cpdi2, 4),
        (ShapeKind::Bspline2, 9),
    ] {
        table.compute(kind, &grid(), &ps).unwrap();
        assert!(table.iter().all(|(_, ws)| ws.len() == expected), "{kind:?}");
        check_invariants(kind, &grid(), &ps, &ps.x);
    }
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
        assert_eq!(table.stride(), kind.max_support());
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
