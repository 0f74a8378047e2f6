//! Tests of the run output: the section of a 3D run's plane pictures and the HDF5 snapshots' layout and units.

use super::cracks::{mid_z, section_layer};
use super::{CONNECTIVITY, FIELDS, Kind, RunOutput, SharedState};
use crate::config::RunConfig;
use hdf5_metno::types::VarLenUnicode;
use nalgebra::Vector2;

const CONFIG: &str = r#"
[run]
name = "io-block"
steps = 1
[grid]
cell_size = 2.0
[shape]
kind = "cpdi1"
points_per_cell = 2
[[body]]
name = "block"
density = 2.4e-9
geometry = { include = [{ type = "rect", min = [0.0, 0.0], max = [6.0, 4.0] }] }
material = { model = "linear_elastic", youngs_modulus = 30000.0, poisson_ratio = 0.2 }
"#;

fn text(loc: &hdf5_metno::Location, name: &str) -> String {
    let v: VarLenUnicode = loc
        .attr(name)
        .and_then(|a| a.read_scalar())
        .unwrap_or_else(|e| panic!("attribute `{name}`: {e}"));
    v.as_str().to_owned()
}

/// The section of a plate: the layer nearest the plane, the lower of two equally near ones whatever
/// round-off the seeded z carry, and all of its points (not those of the neighbouring layers).
#[test]
fn the_section_is_one_layer_the_lower_of_two_equally_near() {
    let z0: Vec<f64> = (0..40)
        .map(|k| [1.0, 3.000_000_000_000_000_4, 4.999_999_999_999_999, 7.0][k % 4])
        .collect();
    assert_eq!(mid_z(&z0), 4.0);
    let (layer, points) = section_layer(&z0, mid_z(&z0));
    assert_eq!(layer, 3.000_000_000_000_000_4);
    assert_eq!(points, (0..40).filter(|k| k % 4 == 1).collect::<Vec<_>>());
    let (layer, points) = section_layer(&z0, 6.5);
    assert_eq!((layer, points.len()), (7.0, 10));
    // One layer (a plane run's z = 0 everywhere): every point.
    assert_eq!(section_layer(&[0.0; 5], 0.0).1.len(), 5);
}

/// Two snapshots of a moved block: the XDMF gives every snapshot a vertex cell per point and
/// 3-component vectors, and the HDF5 files hold what it points to, with units on every dataset.
#[test]
fn snapshots_have_connectivity_3_component_vectors_and_units() {
    let cfg = RunConfig::from_str_named(CONFIG, "io-block.toml").expect("config");
    let mut sim = crate::solver::Simulation::new(crate::scenario::build(&cfg).expect("model"))
        .expect("simulation");
    let dir = std::env::temp_dir().join(format!("mpmc-io-{}", std::process::id()));
    let mut out =
        RunOutput::create(&dir, "io-block", CONFIG, &sim.model, &sim.state).expect("output");
    let session = crate::petsc::Session::get().expect("PETSc");
    let shared = SharedState::new(&session, &sim.state).expect("rows");
    out.snapshot(&shared).expect("snapshot 0");
    drop(shared);
    let n = sim.state.particles.len();
    let p = &mut sim.state.particles;
    for (i, (x, v)) in p.x.iter_mut().zip(&mut p.v).enumerate() {
        *x += Vector2::new(0.5, -0.25 * i as f64);
        *v = Vector2::new(1.0e3, i as f64);
    }
    p.damage[1] = 0.75;
    sim.state.counters.step = 7;
    sim.state.counters.time = 7.0e-6;
    let shared = SharedState::new(&session, &sim.state).expect("rows");
    out.snapshot(&shared).expect("snapshot 7");

    let xdmf = std::fs::read_to_string(dir.join("fields.xdmf")).expect("xdmf");
    for file in ["fields_000000.h5", "fields_000007.h5"] {
        let topology = format!(
            "<Topology TopologyType=\"Polyvertex\" NumberOfElements=\"{n}\" NodesPerElement=\"1\"><DataItem Dimensions=\"{n}\" NumberType=\"Int\" Precision=\"8\" Format=\"HDF\">{file}:/connectivity</DataItem></Topology>"
        );
        assert!(xdmf.contains(&topology), "{topology}\nnot in\n{xdmf}");
        assert!(xdmf.contains(&format!(
            "<Geometry GeometryType=\"XYZ\"><DataItem Dimensions=\"{n} 3\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">{file}:/position</DataItem></Geometry>"
        )));
        for v in ["displacement", "velocity"] {
            assert!(xdmf.contains(&format!(
                "<Attribute Name=\"{v}\" AttributeType=\"Vector\" Center=\"Node\"><DataItem Dimensions=\"{n} 3\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">{file}:/{v}</DataItem></Attribute>"
            )));
        }
    }
    assert!(xdmf.contains("<Time Value=\"7.000000000e-6\"/>"));
    assert!(!xdmf.contains(&format!("Dimensions=\"{n} 2\"")));

    let f = hdf5_metno::File::open(dir.join("fields_000007.h5")).expect("open");
    assert_eq!(text(&f, "units"), "mm, s, N, MPa, t");
    assert_eq!(text(&f, "run_name"), "io-block");
    assert_eq!(text(&f, "config"), CONFIG);
    let step: u64 = f.attr("step").and_then(|a| a.read_scalar()).expect("step");
    let time: f64 = f
        .attr("time_s")
        .and_then(|a| a.read_scalar())
        .expect("time");
    assert_eq!((step, time), (7, 7.0e-6));
    let connectivity: Vec<i64> = f
        .dataset("connectivity")
        .and_then(|d| d.read_raw())
        .expect("connectivity");
    assert_eq!(connectivity, (0..n as i64).collect::<Vec<_>>());
    for field in [&CONNECTIVITY].into_iter().chain(&FIELDS) {
        let ds = f.dataset(field.name).expect(field.name);
        let shape = match field.kind {
            Kind::Scalar => vec![n],
            Kind::Vector => vec![n, 3],
        };
        assert_eq!(ds.shape(), shape, "{}", field.name);
        assert_eq!(text(&ds, "units"), field.units, "{}", field.name);
        assert_eq!(
            text(&ds, "description"),
            field.description,
            "{}",
            field.name
        );
    }
    let read = |name: &str| -> Vec<f64> { f.dataset(name).and_then(|d| d.read_raw()).expect(name) };
    let (position, displacement, velocity) =
        (read("position"), read("displacement"), read("velocity"));
    let p = &sim.state.particles;
    for i in 0..n {
        assert_eq!(position[3 * i..3 * i + 3], [p.x[i].x, p.x[i].y, 0.0]);
        let d = &displacement[3 * i..3 * i + 3];
        assert!(
            (d[0] - 0.5).abs() < 1e-12 && (d[1] + 0.25 * i as f64).abs() < 1e-12 && d[2] == 0.0,
            "point {i}: {d:?}"
        );
        assert_eq!(velocity[3 * i..3 * i + 3], [1.0e3, i as f64, 0.0]);
    }
    assert_eq!(read("damage")[1], 0.75);
    std::fs::remove_dir_all(&dir).ok();
}
