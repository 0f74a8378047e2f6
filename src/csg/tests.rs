use super::*;
use crate::geometry::Seeding;
use crate::particles::Particles;
use nalgebra::{Vector2, Vector3};

/// The geometry of the TOML inline table `text` at the key `body[1].geometry`.
fn shape(text: &str) -> Result<BodyShape, BadValue> {
    let v: toml::Table = toml::from_str(&format!("g = {text}")).unwrap();
    BodyShape::parse(&v["g"], "body[1].geometry")
}

fn space(text: &str) -> SpaceShape {
    match shape(text).unwrap() {
        BodyShape::Space(s) => s,
        other => panic!("not of space: {other:?}"),
    }
}

fn plane(text: &str) -> PlaneShape {
    match shape(text).unwrap() {
        BodyShape::Plane(PlaneGeometry::Shape(s)) => s,
        other => panic!("not plane: {other:?}"),
    }
}

/// Where `x` lies in `s`: 1 inside, 0 on the boundary, -1 outside; panics when the interior is not in
/// the closure.
fn side<P: Primitive<D>, const D: usize>(s: &Shape<P, D>, x: [f64; D]) -> i32 {
    let x = SVector::from(x);
    let (closure, interior) = (s.in_closure(&x), s.in_interior(&x));
    assert!(
        !interior || closure,
        "interior outside the closure at {x:?}"
    );
    match (closure, interior) {
        (true, true) => 1,
        (true, false) => 0,
        _ => -1,
    }
}

#[test]
fn plane_primitives_hold_their_inside_and_their_boundary() {
    let rect = plane(r#"{ type = "rect", min = [0.0, 0.0], max = [4.0, 2.0] }"#);
    assert_eq!(
        [[1.0, 1.0], [4.0, 1.0], [0.0, 0.0], [4.1, 1.0]].map(|x| side(&rect, x)),
        [1, 0, 0, -1]
    );
    let tri = plane(r#"{ type = "polygon", vertices = [[0, 0], [4, 0], [0, 4]] }"#);
    assert_eq!(
        [[1.0, 1.0], [2.0, 2.0], [0.0, 2.0], [3.0, 3.0]].map(|x| side(&tri, x)),
        [1, 0, 0, -1]
    );
    let disk = plane(r#"{ type = "disk", centre = [1.0, 1.0], radius = 5.0 }"#);
    assert_eq!(
        [[1.0, 1.0], [4.0, 5.0], [4.0, 5.1]].map(|x| side(&disk, x)),
        [1, 0, -1]
    );
    // The half-plane y <= 2 (outward normal +y, any length), within a rect.
    let cut = plane(
        r#"{ intersection = [{ type = "rect", min = [0, 0], max = [4, 4] },
                                { type = "half-plane", point = [0, 2], normal = [0, 3] }] }"#,
    );
    assert_eq!(
        [[1.0, 1.0], [1.0, 2.0], [1.0, 3.0], [5.0, 1.0]].map(|x| side(&cut, x)),
        [1, 0, -1, -1]
    );
    assert_eq!(
        cut.bounds(),
        (Vector2::new(0.0, 0.0), Vector2::new(4.0, 4.0))
    );
}

#[test]
fn space_primitives_hold_their_inside_and_their_boundary() {
    let b = space(r#"{ type = "box", min = [0, 0, 0], max = [4, 2, 1] }"#);
    assert_eq!(
        [
            [1.0, 1.0, 0.5],
            [1.0, 1.0, 1.0],
            [4.0, 2.0, 1.0],
            [1.0, 1.0, 1.1]
        ]
        .map(|x| side(&b, x)),
        [1, 0, 0, -1]
    );
    // A cylinder along x from x = 1 to 5, radius 2 about y = z = 0: faces and mantle are boundary.
    let c = space(r#"{ type = "cylinder", from = [1, 0, 0], to = [5, 0, 0], radius = 2.0 }"#);
    assert_eq!(
        [
            [3.0, 1.0, 1.0],
            [1.0, 0.5, 0.0],
            [3.0, 0.0, 2.0],
            [0.9, 0.0, 0.0],
            [3.0, 1.5, 1.5]
        ]
        .map(|x| side(&c, x)),
        [1, 0, 0, -1, -1]
    );
    assert_eq!(
        c.bounds(),
        (Vector3::new(1.0, -2.0, -2.0), Vector3::new(5.0, 2.0, 2.0))
    );
    let s = space(r#"{ type = "sphere", centre = [0, 0, 0], radius = 3.0 }"#);
    assert_eq!(
        [[1.0, 1.0, 1.0], [0.0, 3.0, 0.0], [2.0, 2.0, 2.0]].map(|x| side(&s, x)),
        [1, 0, -1]
    );
    // The half-space x + y <= 2 within a box, and a prism of a disk minus a rect.
    let h = space(
        r#"{ intersection = [{ type = "box", min = [0, 0, 0], max = [2, 2, 2] },
                                { type = "half-space", point = [1, 1, 0], normal = [1, 1, 0] }] }"#,
    );
    assert_eq!(
        [[0.5, 0.5, 1.0], [1.5, 0.5, 1.0], [1.5, 1.5, 1.0]].map(|x| side(&h, x)),
        [1, 0, -1]
    );
    let p = space(
        r#"{ type = "prism", z = [0, 5], section = { difference = [
            { type = "disk", centre = [0, 0], radius = 2.0 }, { type = "rect", min = [0, -3], max = [3, 3] }] } }"#,
    );
    assert_eq!(
        [
            [-1.0, 0.0, 2.0],
            [0.0, 1.0, 2.0],
            [1.0, 0.0, 2.0],
            [-1.0, 0.0, 5.0],
            [-1.0, 0.0, 6.0]
        ]
        .map(|x| side(&p, x)),
        [1, 0, -1, 0, -1]
    );
}

#[test]
fn operations_nest_and_keep_boundaries_consistent() {
    // ((box minus sphere) union small box) intersected with a half-space, on a lattice through faces.
    let s = space(
        r#"{ intersection = [
            { union = [
                { difference = [{ type = "box", min = [0, 0, 0], max = [4, 4, 4] },
                                { type = "sphere", centre = [2, 2, 2], radius = 1.0 }] },
                { type = "box", min = [4, 0, 0], max = [5, 1, 1] } ] },
            { type = "half-space", point = [0, 0, 3], normal = [0, 0, 1] } ] }"#,
    );
    assert_eq!(s.bounds(), (Vector3::zeros(), Vector3::new(5.0, 4.0, 4.0)));
    let expected = [
        ([2.0, 2.0, 2.0], -1), // in the hole
        ([2.0, 2.0, 1.0], 0),  // on the hole's face
        ([0.5, 0.5, 0.5], 1),
        ([4.5, 0.5, 0.5], 1),  // in the small box
        ([4.0, 0.5, 0.5], 0),  // where the boxes touch: boundary of both
        ([0.5, 0.5, 3.0], 0),  // on the half-space's plane
        ([0.5, 0.5, 3.5], -1), // beyond it
    ];
    for (x, want) in expected {
        assert_eq!(side(&s, x), want, "{x:?}");
    }
    // Every lattice point, many of them on faces: the interior lies in the closure (asserted by
    // `side`), and the difference keeps the points on the hole's face.
    let mut on_boundary = 0;
    for k in 0..11 * 11 * 11 {
        let x = [k % 11, (k / 11) % 11, k / 121].map(|i| i as f64 * 0.5);
        on_boundary += (side(&s, x) == 0) as usize;
    }
    assert!(on_boundary > 50, "{on_boundary}");
}

#[test]
fn a_box_minus_a_cylinder_seeds_its_exact_volume_to_the_seeding_resolution() {
    // 20 x 10 x 8 mm minus a hole of radius 3 mm along z through it: 1600 - 72 pi mm^3.
    let s = space(
        r#"{ difference = [{ type = "box", min = [0, 0, 0], max = [20, 10, 8] },
                              { type = "cylinder", from = [10, 5, -1], to = [10, 5, 9], radius = 3.0 }] }"#,
    );
    let exact = 1600.0 - 72.0 * std::f64::consts::PI;
    for (h, tolerance) in [(1.0, 0.01), (0.5, 0.003)] {
        let p = Particles::<3>::seed(&s, &Seeding::concrete(h, 2)).unwrap();
        let volume: f64 = p.vol0.iter().sum();
        assert!(
            (volume / exact - 1.0).abs() < tolerance,
            "h = {h}: {volume} vs {exact}"
        );
        assert!(
            p.x.iter()
                .all(|x| (x.xy() - Vector2::new(10.0, 5.0)).norm() >= 3.0)
        );
    }
    // A box on the lattice seeds its volume exactly, also as a prism of a rect.
    let b = space(
        r#"{ type = "prism", z = [0, 8], section = { type = "rect", min = [0, 0], max = [20, 10] } }"#,
    );
    let p = Particles::<3>::seed(&b, &Seeding::concrete(1.0, 2)).unwrap();
    assert_eq!(p.len(), 8 * 1600);
}

#[test]
fn a_prism_seeds_the_points_of_its_section_in_layers() {
    // A plate with a hole as a prism 3 mm thick seeds, layer by layer, the points the plane geometry
    // seeds, with their volume times the point spacing: what [extrusion] does with a plane body.
    let section = r#"{ difference = [{ type = "rect", min = [0, 0], max = [12, 6] },
                                     { type = "disk", centre = [6, 3], radius = 2.0 }] }"#;
    let plate = Particles::<2>::seed(&plane(section), &Seeding::concrete(1.0, 2)).unwrap();
    let prism = space(&format!(
        r#"{{ type = "prism", z = [0, 3], section = {section} }}"#
    ));
    let solid = Particles::<3>::seed(&prism, &Seeding::concrete(1.0, 2)).unwrap();
    assert_eq!(solid.len(), 6 * plate.len());
    for k in 0..6 {
        let z = 0.25 + 0.5 * k as f64;
        let layer: Vec<Vector2<f64>> = solid
            .x
            .iter()
            .filter(|x| x.z == z)
            .map(|x| x.xy())
            .collect();
        assert_eq!(layer, plate.x, "layer {k}");
    }
    let volume = |v: &[f64]| v.iter().sum::<f64>();
    assert!((volume(&solid.vol0) - 3.0 * volume(&plate.vol0)).abs() < 1e-9);
}

/// The error of the geometry `text` at `body[1].geometry`, as `key = value: allowed`.
fn refusal(text: &str) -> String {
    let e = shape(text).unwrap_err();
    format!("{} = {}: {}", e.key, e.value, e.allowed)
}

#[test]
fn bad_geometries_are_refused_naming_the_key() {
    let cases = [
        (
            r#"{ difference = [{ type = "box", min = [0, 0, 0], max = [1, 1, 1] },
                               { type = "cylinder", from = [0, 0, 0], to = [0, 0, 1], radius = 0.0 }] }"#,
            "body[1].geometry.difference[1].radius = 0: a radius > 0",
        ),
        (
            r#"{ type = "box", min = [0, 0, 0], max = [1, -1, 1] }"#,
            "body[1].geometry.max = [1.0, -1.0, 1.0] with min = [0.0, 0.0, 0.0]: max > min",
        ),
        (
            r#"{ union = [{ type = "sphere", centre = [0, 0, 0], radius = 1.0 }, { type = "ball" }] }"#,
            "body[1].geometry.union[1].type = \"ball\": one of [\"box\", \"cylinder\", \"sphere\", \
             \"half-space\", \"prism\"]",
        ),
        (
            r#"{ type = "half-space", point = [0, 0, 0], normal = [0, 0, 1] }"#,
            "body[1].geometry = an unbounded geometry: a bounded one",
        ),
        (
            r#"{ union = [{ type = "box", min = [0, 0, 0], max = [1, 1, 1] },
                          { type = "half-space", point = [0, 0, 0], normal = [0, 0, 1] }] }"#,
            "an unbounded geometry",
        ),
        (
            r#"{ intersection = [{ type = "box", min = [0, 0, 0], max = [1, 1, 1] },
                                 { type = "box", min = [2, 0, 0], max = [3, 1, 1] }] }"#,
            "body[1].geometry = a geometry with no material",
        ),
        (
            r#"{ difference = [{ type = "disk", centre = [0, 0], radius = 1.0 }] }"#,
            "body[1].geometry.difference = 1 geometries: at least two",
        ),
        (
            r#"{ type = "sphere", centre = [0, 0], radius = 1.0 }"#,
            "body[1].geometry.centre = [0, 0]: 3 components (mm), not 2",
        ),
        (
            r#"{ type = "disk", centre = [0, 0, 0], radius = 1.0 }"#,
            "body[1].geometry.centre = [0, 0, 0]: 2 components (mm), not 3",
        ),
        (
            r#"{ difference = [{ type = "box", min = [0, 0, 0], max = [1, 1, 1] },
                               { type = "disk", centre = [0, 0], radius = 1.0 }] }"#,
            "body[1].geometry.difference[1].type = \"disk\": one of",
        ),
        (
            r#"{ type = "sphere", centre = [0, 0, 0], r = 1.0 }"#,
            "unknown field `r`",
        ),
        (
            r#"{ type = "prism", z = [0, 1], section = { type = "disk", centre = [0, 0], radius = -1.0 } }"#,
            "body[1].geometry.section.radius = -1: a radius > 0",
        ),
        (
            r#"{ type = "half-plane", point = [0, 0], normal = [0, 0] }"#,
            "body[1].geometry.normal = [0.0, 0.0]: a finite non-zero vector",
        ),
        (
            r#"{ union = [], difference = [] }"#,
            "body[1].geometry = a table with the keys [\"difference\", \"union\"]",
        ),
        (
            r#"{ type = "cylinder", from = [1, 1, 1], to = [1, 1, 1], radius = 1.0 }"#,
            "body[1].geometry.to",
        ),
    ];
    for (text, want) in cases {
        let got = refusal(text);
        assert!(got.contains(want), "{text}\n got: {got}\nwant: {want}");
    }
}
