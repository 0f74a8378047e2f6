//! Stress-strain curves of the microplane presets for the documentation, and their implied strengths.
//!
//! ```text
//! cargo run --release --example material_curves [-- <output dir, default docs/img>]
//! ```
//! Writes `material-<preset>-{tension,compression,cyclic}.png` and prints the strengths.

use mpm_concrete::app::material_driver::path_plot;
use mpm_concrete::material::driver::{EtaBarPath, PathKind, peak, run_path, uniaxial_strengths};
use mpm_concrete::material::{MaterialConfig, MicroplaneConfig, Preset};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out =
        std::path::PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "docs/img".into()));
    for (preset, short) in [
        (Preset::Paper, "paper"),
        (Preset::PaperGamma0Low, "gamma0-1.25e-4"),
    ] {
        let m = MaterialConfig::Microplane(MicroplaneConfig::preset(preset)).build()?;
        let g0 = preset.params().gamma_0;
        let s = uniaxial_strengths(&m, 4000)?.ok_or("not a microplane")?;
        println!(
            "{}: tensile {:.3} MPa at {:.4e}, compressive {:.3} MPa at {:.4e}, ratio {:.3}",
            preset.name(),
            s.tensile,
            s.tensile_strain,
            s.compressive,
            s.compressive_strain,
            s.compressive / s.tensile
        );
        for (kind, max, label) in [
            (PathKind::UniaxialTension, 10.0 * g0, "tension"),
            (PathKind::UniaxialCompression, 40.0 * g0, "compression"),
            (PathKind::CyclicTension, 6.0 * g0, "cyclic"),
        ] {
            let pts = run_path(&m, kind, max, 600, EtaBarPath::Local)?;
            let (p, e) = peak(&pts, kind);
            println!("  {label}: peak {p:.3} MPa at {e:.4e}");
            let title = format!("{}, local, preset {}", kind.name(), preset.name());
            path_plot(&pts, kind, &title)
                .save_png(out.join(format!("material-{short}-{label}.png")))?;
        }
    }
    Ok(())
}
