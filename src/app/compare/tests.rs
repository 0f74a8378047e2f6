use super::run_data::read_dataset;
use super::*;

#[test]
fn every_quantity_reads_a_field_the_writer_writes() {
    for (quantity, dataset, component) in QUANTITIES {
        let field = crate::io::FIELDS
            .iter()
            .find(|f| f.name == dataset)
            .unwrap_or_else(|| panic!("`{quantity}` reads `{dataset}`, which io does not write"));
        assert_eq!(
            component.is_some(),
            field.kind == crate::io::Kind::Vector,
            "{quantity}: component of a vector field, none of a scalar"
        );
    }
}

/// A regular lattice of points over [0, 10] x [0, 5], spacing 0.5, offset by a quarter spacing (like
/// material points in their cells).
fn lattice() -> Vec<[f64; 2]> {
    let mut pts = Vec::new();
    for j in 0..10 {
        for i in 0..20 {
            pts.push([0.125 + 0.5 * i as f64, 0.125 + 0.5 * j as f64]);
        }
    }
    pts
}

#[test]
fn vectors_are_read_as_xy_pairs_from_3_and_2_component_snapshots() {
    let dir = std::env::temp_dir().join(format!("mpmc-compare-read-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("fields.h5");
    {
        let f = hdf5_metno::File::create(&path).expect("create");
        let put = |name: &str, data: ndarray::ArrayD<f64>| {
            f.new_dataset_builder()
                .with_data(&data)
                .create(name)
                .expect("dataset");
        };
        let xyz = ndarray::arr2(&[[1.0, 2.0, 0.0], [3.0, 4.0, 0.0]]);
        put("xyz", xyz.into_dyn());
        put("xy", ndarray::arr2(&[[1.0, 2.0], [3.0, 4.0]]).into_dyn());
        put("scalar", ndarray::arr1(&[5.0, 6.0]).into_dyn());
    }
    for name in ["xyz", "xy"] {
        let v = read_dataset(&path, name, Some(2), true).expect(name);
        assert_eq!(v, [1.0, 2.0, 3.0, 4.0], "{name}");
    }
    let s = read_dataset(&path, "scalar", None, false).expect("scalar");
    assert_eq!(s, [5.0, 6.0]);
    let e = read_dataset(&path, "xyz", Some(3), true)
        .unwrap_err()
        .to_string();
    assert!(e.contains("shape [2, 3], expected (3, 3)"), "{e}");
    let e = read_dataset(&path, "scalar", None, true)
        .unwrap_err()
        .to_string();
    assert!(e.contains("shape [2], expected (N, 3)"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn fit_reproduces_a_linear_field_inside_and_extrapolated_at_corners() {
    let index = PointIndex::new(lattice());
    let f = |p: [f64; 2]| 3.5 - 0.7 * p[0] + 2.25 * p[1];
    let pts = index.points().to_vec();
    let values: Vec<f64> = pts.iter().map(|&p| f(p)).collect();
    for at in [[0.0, 0.0], [10.0, 5.0], [0.0, 5.0], [4.3, 2.1], [10.0, 2.6]] {
        let near = index.nearest(at, 12);
        assert_eq!(near.len(), 12);
        let p: Vec<[f64; 2]> = near.iter().map(|&i| pts[i]).collect();
        let v: Vec<f64> = near.iter().map(|&i| values[i]).collect();
        let got = linear_fit(&p, &v, at).expect("fit");
        assert!(
            (got - f(at)).abs() <= 1e-12 * f(at).abs().max(1.0),
            "at {at:?}: {got} vs {}",
            f(at)
        );
    }
}

#[test]
fn fit_of_collinear_points_is_refused() {
    let pts: Vec<[f64; 2]> = (0..6).map(|i| [i as f64, 2.0 * i as f64]).collect();
    let vals: Vec<f64> = (0..6).map(|i| i as f64).collect();
    assert_eq!(linear_fit(&pts, &vals, [1.0, 1.0]), None);
    assert_eq!(linear_fit(&pts[..2], &vals[..2], [1.0, 1.0]), None);
}

#[test]
fn nearest_matches_brute_force() {
    // Deterministic scattered points (a linear congruential sequence), some queries outside.
    let mut seed = 12345u64;
    let mut next = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let pts: Vec<[f64; 2]> = (0..500).map(|_| [100.0 * next(), 20.0 * next()]).collect();
    let index = PointIndex::new(pts.clone());
    let queries = [
        [50.0, 10.0],
        [-30.0, -5.0],
        [130.0, 40.0],
        [0.0, 10.0],
        [99.0, 0.5],
    ];
    for q in queries {
        let got = index.nearest(q, 12);
        let mut all: Vec<(f64, usize)> = pts
            .iter()
            .enumerate()
            .map(|(i, p)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2), i))
            .collect();
        all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let want: Vec<usize> = all[..12].iter().map(|a| a.1).collect();
        assert_eq!(got, want, "query {q:?}");
    }
    assert_eq!(index.nearest([0.0, 0.0], 1000).len(), 500);
    assert!(
        PointIndex::new(Vec::new())
            .nearest([0.0, 0.0], 3)
            .is_empty()
    );
}

#[test]
fn interpolation_in_time() {
    let t = [1.0e-6, 2.0e-6, 3.0e-6, 5.0e-6];
    let v = [10.0, 20.0, 40.0, 0.0];
    let tol = 1e-12;
    assert_eq!(interpolate(&t, &v, 2.0e-6, tol), Some(20.0));
    assert_eq!(interpolate(&t, &v, 5.0e-6, tol), Some(0.0));
    let mid = interpolate(&t, &v, 2.5e-6, tol).expect("inside");
    assert!((mid - 30.0).abs() < 1e-9);
    let late = interpolate(&t, &v, 4.5e-6, tol).expect("inside");
    assert!((late - 10.0).abs() < 1e-9);
    // Round-off at the ends is accepted, more is not.
    assert_eq!(interpolate(&t, &v, 5.0e-6 + 1e-13, tol), Some(0.0));
    assert_eq!(interpolate(&t, &v, 1.0e-6 - 1e-13, tol), Some(10.0));
    assert_eq!(interpolate(&t, &v, 5.1e-6, tol), None);
    assert_eq!(interpolate(&t, &v, 0.0, tol), None);
    // A single sample.
    assert_eq!(interpolate(&[4e-3], &[7.0], 4e-3, tol), Some(7.0));
    assert_eq!(interpolate(&[], &[], 0.0, tol), None);
}

#[test]
fn relative_errors_and_zero_references() {
    let (l2, max, at) = relative_errors(&[1.0, -2.0, 2.0], &[1.0, -2.0, 2.2]);
    assert!((l2 - 0.2 / 3.0).abs() < 1e-12);
    assert!((max - 0.1).abs() < 1e-12);
    assert_eq!(at, 2);
    assert_eq!(relative_errors(&[0.0, 0.0], &[0.0, 0.0]).0, 0.0);
    assert_eq!(relative_errors(&[0.0, 0.0], &[0.0, 1e-9]).1, f64::INFINITY);
}

#[test]
fn reference_kinds_and_messages() {
    let h = parse_reference(
        "# a comment\ntime,load_fy\n1e-6,2.0\n\n# more\n2e-6,3.0\n",
        "h.csv",
    )
    .expect("history");
    match h {
        Reference::History(h) => {
            assert_eq!(h.columns, ["load_fy"]);
            assert_eq!(h.rows, vec![(3, 1e-6, vec![2.0]), (6, 2e-6, vec![3.0])]);
        }
        Reference::Point(_) => panic!("not a point reference"),
    }
    let p = parse_reference("time,x,y,quantity,value\n0.1,1,2,sigma_xx,-3.5\n", "p.csv")
        .expect("points");
    assert!(matches!(p, Reference::Point(ref p) if p.rows[0].quantity == 4));
    let err = |text: &str| parse_reference(text, "r.csv").unwrap_err().to_string();
    for (text, start) in [
        (
            "time,x,y,quantity,value\n0.1,1,2,strain,1\n",
            "r.csv:2: quantity `strain` is unknown; allowed: ux, uy",
        ),
        ("t,load\n1,2\n", "r.csv:1: header `t,load`: expected"),
        ("time,a\n1,2\n3\n", "r.csv:3: 1 fields, the header has 2"),
        (
            "time,a\n1,abc\n",
            "r.csv:2: `a` = `abc` is not a finite number",
        ),
    ] {
        let e = err(text);
        assert!(e.starts_with(start), "{e}");
    }
    for (text, part) in [
        ("time,a,a\n1,2,3\n", "appears twice"),
        ("# only a comment\n", "no header"),
        ("time,a\n", "no data rows"),
    ] {
        let e = err(text);
        assert!(e.contains(part), "{e}");
    }
}
