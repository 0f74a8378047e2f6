//! Tests of the configuration: parsing, overrides, the effective text and the checks' messages.

use super::*;
use crate::model::{InitialAcceleration, Method, TimeIntegration};
use crate::shape::ShapeKind;

/// Every configuration the repository ships parses and validates (a renamed field breaks no run
/// unnoticed), and the 3D demo is the plane demo extruded.
#[test]
fn an_empty_time_section_gives_the_models_default_time_integration() {
    assert_eq!(
        TimeSection::default().integration(),
        TimeIntegration::default()
    );
    let t = TimeSection {
        dt: 2e-7,
        ..TimeSection::default()
    };
    assert_eq!(t.integration(), TimeIntegration::with_dt(2e-7));
    assert_eq!(t.integration().dt_min, 2e-7 / 64.0);
}

#[test]
fn the_shipped_configurations_are_valid() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let mut checked = 0;
    for sub in [dir.clone(), dir.join("bench")] {
        for entry in std::fs::read_dir(&sub).expect("configs/") {
            let path = entry.expect("entry").path();
            if path.extension().is_some_and(|e| e == "toml") {
                RunConfig::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
                checked += 1;
            }
        }
    }
    assert!(checked >= 13, "{checked} configurations");
    for (plane, plate) in [
        ("ct-demo.toml", "ct-3d-demo.toml"),
        ("ct-demo-c1.toml", "ct-3d-demo-c1.toml"),
    ] {
        let plane = RunConfig::from_file(&dir.join(plane)).expect(plane);
        let plate = RunConfig::from_file(&dir.join(plate)).expect(plate);
        assert!(plane.extrusion.is_none());
        assert_eq!(plate.extrusion.map(|e| e.thickness), Some(8.0));
        assert_eq!(format!("{:?}", plane.ct), format!("{:?}", plate.ct));
    }
}

/// The override that gives a CT configuration the paper's constant `c = 1 mm^2` (`docs/configuration.md`,
/// "The regularisation of the CT configurations").
const PAPER_CONSTANT: &str =
    r#"ct.material={ model = "microplane", preset = "paper", erosion_damage = 0.95 }"#;

/// The CT configurations run the converged regularisation (`c_0 = 9 mm^2`, localizing activity with
/// residual 0.45 and decay 0), and the paper's constant is one override away: each `-c1` file is its
/// sibling with the override, the same effective configuration but for the run's name. So the runs of the
/// old setting in the docs, whose commands name the `-c1` files, keep their results.
#[test]
fn the_ct_configurations_default_to_the_converged_choice_and_the_c1_files_are_one_override_away() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let converged = crate::material::GradientActivity::Localizing {
        residual: 0.45,
        decay: 0.0,
    };
    let pairs = [
        ("ct-paper-4.3mps", "ct-paper-c1-4.3mps"),
        ("ct-paper-1.4mps", "ct-paper-c1-1.4mps"),
        ("ct-paper-0.035mps", "ct-paper-c1-0.035mps"),
        ("ct-paper-0.035mps-10ms", "ct-paper-c1-0.035mps-10ms"),
        ("ct-paper-h2-4.3mps", "ct-paper-c1-h2-4.3mps"),
        ("ct-paper-h2-1.4mps", "ct-paper-c1-h2-1.4mps"),
        ("ct-paper-h2-0.035mps-10ms", "ct-paper-c1-h2-0.035mps-10ms"),
        ("ct-demo", "ct-demo-c1"),
        ("ct-3d-demo", "ct-3d-demo-c1"),
    ];
    let without_name = |text: &str| {
        let mut t: toml::Table = toml::from_str(text).expect("canonical text");
        t["run"].as_table_mut().expect("[run]").remove("name");
        t
    };
    for (default, c1) in pairs {
        let default_path = dir.join(format!("{default}.toml"));
        let c1_path = dir.join(format!("{c1}.toml"));
        let (cfg, _) = RunConfig::load(&default_path, &[]).expect(default);
        let m = cfg.materials().concrete.as_ref().expect(default);
        assert_eq!(m.gradient_parameter(), 9.0, "{default}");
        assert_eq!(m.gradient_activity(), converged, "{default}");
        let (old, old_text) = RunConfig::load(&c1_path, &[]).expect(c1);
        let m = old.materials().concrete.as_ref().expect(c1);
        assert_eq!(m.gradient_parameter(), 1.0, "{c1}");
        assert_eq!(
            m.gradient_activity(),
            crate::material::GradientActivity::Constant,
            "{c1}"
        );
        let (overridden, text) =
            RunConfig::load(&default_path, &[PAPER_CONSTANT.to_string()]).expect(default);
        assert_eq!(
            without_name(&text),
            without_name(&old_text),
            "{default} vs {c1}"
        );
        assert_eq!(
            format!("{:?}", overridden.materials()),
            format!("{:?}", old.materials()),
            "{default} vs {c1}"
        );
    }
    // The configurations without a `-c1` file take the same override (the inserts' CT, docs/results.md).
    let (inserts, _) = RunConfig::load(
        &dir.join("ct-paper-4.3mps-inserts.toml"),
        &[PAPER_CONSTANT.to_string()],
    )
    .expect("inserts");
    let (old, _) = RunConfig::load(&dir.join("ct-paper-c1-4.3mps.toml"), &[]).expect("c1");
    assert_eq!(
        format!("{:?}", inserts.materials().concrete),
        format!("{:?}", old.materials().concrete)
    );
}

const MINIMAL: &str = r#"
[run]
name = "t"
steps = 2
[grid]
cell_size = 1.0
[[body]]
name = "b"
density = 1e-9
geometry = { include = [{ type = "rect", min = [0.0, 0.0], max = [2.0, 2.0] }] }
material = { model = "svk", youngs_modulus = 100.0, poisson_ratio = 0.2 }
[[constraint]]
name = "base"
min = [-1.0, -0.1]
max = [3.0, 0.1]
y = "fixed"
x = { velocity = 5.0 }
"#;

#[test]
fn minimal_config_parses_with_defaults() {
    let c = RunConfig::from_str_named(MINIMAL, "t.toml").expect("valid");
    assert_eq!(c.time.beta, 0.25);
    assert_eq!(c.time.initial_acceleration, InitialAcceleration::Consistent);
    assert_eq!(c.shape.kind, ShapeKind::Cpdi1);
    assert_eq!(c.constraint[0].x, MotionSpec::Velocity { velocity: 5.0 });
    assert_eq!(c.constraint[0].y, MotionSpec::Keyword(Keyword::Fixed));
}

#[test]
fn errors_name_file_field_and_allowed_range() {
    let neg = MINIMAL.replace("[grid]", "[time]\ndt = -1e-6\n[grid]");
    let e = RunConfig::from_str_named(&neg, "t.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("t.toml") && e.contains("time.dt") && e.contains("[1e-12, 1000] s"),
        "{e}"
    );
    let typo = MINIMAL.replace("cell_size", "cell_sise");
    let e = RunConfig::from_str_named(&typo, "t.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("t.toml") && e.contains("cell_sise"), "{e}");
    assert!(
        !e.contains('\n') && e.contains("line 6, column 1") && e.contains("(in [grid])"),
        "one line with the position and the table: {e}"
    );
    let start = MINIMAL.replace("[grid]", "[time]\ninitial_acceleration = \"rest\"\n[grid]");
    let e = RunConfig::from_str_named(&start, "t.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("t.toml")
            && e.contains("time.initial_acceleration")
            && e.contains("\"rest\"")
            && e.contains("\"consistent\"")
            && e.contains("\"zero\""),
        "{e}"
    );
    let beta0 = MINIMAL.replace("[grid]", "[time]\nbeta = 0.0\n[grid]");
    let e = RunConfig::from_str_named(&beta0, "t.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("time.beta"), "{e}");
}

#[test]
fn overrides_and_fem_mode_are_validated() {
    let path = std::env::temp_dir().join(format!("mpmc-cfg-{}.toml", std::process::id()));
    std::fs::write(&path, MINIMAL).unwrap();
    let set = |o: &[&str]| {
        RunConfig::load(&path, &o.iter().map(|s| s.to_string()).collect::<Vec<_>>()).map(|(c, _)| c)
    };
    let c = set(&[
        "shape.method=fem",
        "shape.kind=linear",
        "grid.cell_size=2.5",
    ])
    .unwrap();
    assert_eq!(c.shape.method, Method::Fem);
    assert_eq!(c.grid.cell_size, 2.5);
    // FEM needs the bilinear interpolator and 1-3 Gauss points.
    let e = set(&["shape.method=fem"]).unwrap_err().to_string();
    assert!(e.contains("shape.kind") && e.contains("linear"), "{e}");
    let e = set(&["shape.method=\"fe\""]).unwrap_err().to_string();
    assert!(e.contains("--set") && e.contains("method"), "{e}");
    let e = set(&["grid.cell_size"]).unwrap_err().to_string();
    assert!(e.contains("key=value"), "{e}");
    // The CPDI corner hold: plain CPDI by default, at most a quarter cell.
    assert_eq!(set(&[]).unwrap().shape.corner_hold, 0.0);
    assert_eq!(
        set(&["shape.corner_hold=0.1"]).unwrap().shape.corner_hold,
        0.1
    );
    let e = set(&["shape.corner_hold=0.5"]).unwrap_err().to_string();
    assert!(e.contains("shape.corner_hold") && e.contains("0.25"), "{e}");
    let e = set(&["shape.corner_hold=0.1", "shape.kind=\"gimp\""])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("shape.corner_hold") && e.contains("cpdi1"),
        "{e}"
    );
    std::fs::remove_file(&path).ok();
}

#[test]
fn effective_text_includes_the_overrides_and_ignores_formatting() {
    let dir = std::env::temp_dir().join(format!("mpmc-cfg-eff-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (a, b) = (dir.join("a.toml"), dir.join("b.toml"));
    std::fs::write(&a, MINIMAL).unwrap();
    let reformatted = format!(
        "# a comment\n{}",
        MINIMAL.replace("steps = 2", "steps   =   2 # two")
    );
    std::fs::write(&b, reformatted).unwrap();
    let (_, ta) = RunConfig::load(&a, &[]).unwrap();
    let (_, tb) = RunConfig::load(&b, &[]).unwrap();
    assert_eq!(
        ta, tb,
        "comments and spacing do not change the effective text"
    );
    let (c, tc) = RunConfig::load(&a, &["grid.cell_size=0.5".to_string()]).unwrap();
    assert_eq!(c.grid.cell_size, 0.5);
    assert!(tc.contains("cell_size = 0.5"), "{tc}");
    let again = RunConfig::from_str_named(&tc, "effective").unwrap();
    assert_eq!(again.grid.cell_size, 0.5);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn non_finite_negative_and_inconsistent_values_are_rejected() {
    let ct = |extra: &str| {
        format!(
            "[run]\nname = \"c\"\nsteps = 1\n[grid]\ncell_size = 4.0\n[ct]\nloading_rate = 4300.0\n\
             material = {{ model = \"svk\", youngs_modulus = 100.0, poisson_ratio = 0.2 }}\n{extra}"
        )
    };
    let cases: Vec<(String, &str)> = vec![
        (ct("rise_time = -1e-6"), "ct.rise_time"),
        (ct("rise_time = nan"), "ct.rise_time"),
        (ct("load_zone = [-100.0, -50.0]"), "ct.load_zone"),
        (ct("density = inf"), "ct.density"),
        (ct("width = nan"), "ct.width"),
        (
            MINIMAL.replace("y = \"fixed\"", "y = { velocity = nan }"),
            "constraint[0].y",
        ),
        (
            MINIMAL.replace("max = [3.0, 0.1]", "max = [inf, 0.1]"),
            "constraint[0].min/max",
        ),
        (
            MINIMAL.replace(
                "material = {",
                "initial_velocity = [nan, 0.0]\nmaterial = {",
            ),
            "body[0].initial_velocity",
        ),
        (
            MINIMAL.replace("y = \"fixed\"", "y = \"fixed\"\nrise_time = -1.0"),
            "constraint[0].rise_time",
        ),
        (
            MINIMAL.replace("max = [2.0, 2.0]", "max = [-2.0, 2.0]"),
            "body[0].geometry",
        ),
        (MINIMAL.replace("name = \"t\"", "name = \"\""), "run.name"),
        (
            MINIMAL.replace("name = \"base\"", "name = \"a,b\""),
            "constraint[0].name",
        ),
        (
            format!(
                "{MINIMAL}\n[[constraint]]\nname = \"base\"\nmin = [0.0, 0.0]\nmax = [1.0, 1.0]\n"
            ),
            "constraint[1].name",
        ),
        (format!("body_force = [0.0, nan]\n{MINIMAL}"), "body_force"),
    ];
    for (text, field) in cases {
        let e = RunConfig::from_str_named(&text, "t.toml")
            .expect_err(field)
            .to_string();
        assert!(
            e.starts_with("t.toml: field `") && e.contains(field),
            "{field}: {e}"
        );
    }
}

/// A value that the scenario or the model refuses reads like the configuration's own checks: the file,
/// the key path, the value and what is allowed.
#[test]
fn scenario_and_model_refusals_name_the_key() {
    let refused = |text: &str| {
        let cfg = RunConfig::from_str_named(text, "t.toml").expect("valid");
        let e = match crate::scenario::build(&cfg) {
            Err(e) => e.in_file("t.toml"),
            Ok(setup) => match crate::model::Model::new(setup) {
                Err(crate::model::ModelError::Invalid(bad)) => ConfigError::in_file("t.toml", bad),
                _ => panic!("accepted: {text}"),
            },
        };
        e.to_string()
    };
    let far_box = MINIMAL.replace("max = [3.0, 0.1]", "max = [3.0, -50.0]");
    let far_box = far_box.replace("min = [-1.0, -0.1]", "min = [-1.0, -60.0]");
    let e = refused(&far_box);
    assert!(
        e.starts_with("t.toml: field `constraint[0]` = `base`, the box")
            && e.contains("holds no grid node"),
        "{e}"
    );
    let off_grid = format!(
        "{MINIMAL}[[load]]\nname = \"pull\"\nfrom = [0.5, 0.0]\nto = [0.5, 2.0]\nforce = [1.0, 0.0]\n"
    );
    let e = refused(&off_grid);
    assert!(
        e.starts_with("t.toml: field `load[0]` = `pull` from [0.5, 0.0] to [0.5, 2.0]: a segment on a grid line"),
        "{e}"
    );
}
