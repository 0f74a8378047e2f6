//! Geometries of primitives combined by union, intersection and difference (`[[body]]` geometry,
//! docs/configuration.md): the 3D example (a notched beam with a hole and a void) and the 2D one (a plate
//! with a hole) seed what their geometry holds and run on the real binary; bad geometries are refused by
//! the binary with exit code 2 and one line naming the key.
//!
//! Units: mm, s, N, MPa, t.

mod binary;

use binary::{refused, run, scratch, stderr, succeeds};
use mpm_concrete::config::RunConfig;
use mpm_concrete::scenario::{self, RunSetup};
use nalgebra::Vector2;
use std::path::{Path, PathBuf};

/// A configuration of the repository.
fn config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs")
        .join(name)
}

#[test]
fn the_3d_beam_seeds_around_its_notch_hole_and_void() {
    let cfg = RunConfig::from_file(&config("beam-3d-holes.toml")).expect("config");
    let Ok(RunSetup::Plate(setup)) = scenario::build_run(scenario::plan(&cfg).expect("plan"))
    else {
        panic!("a run in 3D");
    };
    let x = &setup.particles.x;
    // 24 x 6 x 4 cells of 2.5 mm with 8 points each, minus 48 in the notch, 144 in the hole (12 per layer
    // of y) and 56 in the void.
    assert_eq!(x.len(), 4608 - 48 - 144 - 56);
    assert!(x.iter().all(|p| !(p.x > 29.0 && p.x < 31.0 && p.y < 4.0)));
    assert!(
        x.iter()
            .all(|p| (Vector2::new(p.x, p.z) - Vector2::new(15.0, 5.0)).norm() > 2.5)
    );
    assert!(
        x.iter()
            .all(|p| (p - nalgebra::Vector3::new(45.0, 7.5, 5.0)).norm() > 3.0)
    );
    let (lo, hi) = setup.particles.bounding_box().expect("points");
    assert_eq!((lo.x, lo.z, hi.x, hi.z), (0.0, 0.0, 60.0, 10.0));
    // The grid covers the beam and the rigid bodies with 2 cells of margin in the plane and the
    // plate's 2 cells in z.
    let g = &setup.params.grid;
    assert_eq!((g.nx(), g.ny(), g.nz()), (28, 12, 8));
    assert_eq!(setup.rigid_points.len(), 3);
}

#[test]
fn the_examples_run_two_steps_on_the_binary() {
    let dir = scratch("csg", "examples", &[]);
    for (name, header) in [
        (
            "beam-3d-holes.toml",
            "4360 material points, grid 28x12x8 cells of 2.5 mm, a 10 mm plate (3D)",
        ),
        ("plate-hole-2d.toml", "4684 material points, grid 56x31"),
    ] {
        let file = config(name);
        let out = name.replace(".toml", "");
        let o = run(
            &dir,
            &[
                "run",
                file.to_str().unwrap(),
                "--steps",
                "2",
                "--output",
                &out,
            ],
        );
        succeeds(&o);
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(stderr(&o).contains(header), "{stdout}{}", stderr(&o));
        assert!(stdout.contains("| steps | 2 (0 retried"), "{stdout}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_geometries_are_refused_on_the_binary_naming_the_key() {
    let dir = scratch("csg", "refusals", &[]);
    let beam = config("beam-3d-holes.toml");
    let plate = config("plate-hole-2d.toml");
    let set = |g: &str| format!("body[0].geometry={g}");
    let cases: Vec<(&Path, String, Vec<&str>)> = vec![
        (
            &beam,
            set(
                r#"{difference=[{type="box",min=[0,0,0],max=[60,15,10]},{type="cylinder",from=[15,-1,5],to=[15,16,5],radius=0}]}"#,
            ),
            vec![
                "`body[0].geometry.difference[1].radius` = 0",
                "a radius > 0 (mm)",
            ],
        ),
        (
            &beam,
            set(r#"{type="box",min=[0,0,0],max=[60,-15,10]}"#),
            vec!["`body[0].geometry.max`", "max > min in every direction"],
        ),
        (
            &beam,
            set(r#"{union=[{type="box",min=[0,0,0],max=[60,15,10]},{type="cone",radius=1}]}"#),
            vec!["`body[0].geometry.union[1].type` = \"cone\"", "\"sphere\""],
        ),
        (
            &beam,
            set(r#"{type="half-space",point=[0,0,0],normal=[0,1,0]}"#),
            vec!["`body[0].geometry` = an unbounded geometry", "intersect it"],
        ),
        (
            &beam,
            set(
                r#"{intersection=[{type="box",min=[0,0,0],max=[10,15,10]},{type="sphere",centre=[50,7,5],radius=3}]}"#,
            ),
            vec!["`body[0].geometry` = a geometry with no material"],
        ),
        (
            &beam,
            set(
                r#"{difference=[{type="box",min=[0,0,0],max=[60,15,10]},{type="box",min=[-1,-1,-1],max=[61,16,11]}]}"#,
            ),
            vec!["`body[0].geometry` = `beam`", "(this one holds none)"],
        ),
        (
            &beam,
            set(r#"{type="box",min=[0,0,0],max=[60,15,12]}"#),
            vec![
                "`body[0].geometry` = (a geometry of space from z = 0 to 12 mm)",
                "extrusion.thickness = 10 mm",
            ],
        ),
        (
            &plate,
            set(r#"{type="sphere",centre=[50,25,5],radius=10}"#),
            vec!["`body[0].geometry` = (a geometry of space)", "[extrusion]"],
        ),
        (
            &plate,
            set(
                r#"{difference=[{type="rect",min=[0,0],max=[100,50]},{type="disk",centre=[50,25,0],radius=10}]}"#,
            ),
            vec![
                "`body[0].geometry.difference[1].centre`",
                "2 components (mm), not 3",
            ],
        ),
    ];
    // A key inside the file's geometry, reached by --set.
    let hole = (
        beam.as_path(),
        "body[0].geometry.difference[2].radius=0".to_owned(),
        vec!["`body[0].geometry.difference[2].radius` = 0: a radius > 0 (mm)"],
    );
    for (file, geometry, needles) in cases.into_iter().chain([hole]) {
        let o = run(
            &dir,
            &[
                "run",
                file.to_str().unwrap(),
                "--set",
                &geometry,
                "--output",
                "out",
            ],
        );
        refused(&o, &needles);
        assert!(!dir.join("out").exists(), "{geometry}: nothing is written");
    }
    std::fs::remove_dir_all(&dir).ok();
}
