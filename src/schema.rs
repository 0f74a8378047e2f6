//! The names of a run directory's files, shared by the writers (`io`, `checkpoint`, `rundir`, the `run`
//! command) and the readers (`app::compare`, `app::study`), and the table of the columns of
//! `history.csv` (name, unit, meaning and value of each), so that a renamed or added column or file
//! changes in one place.
//!
//! Units of the history columns: time and dt s, displacement mm, force N per mm thickness (3D: N),
//! rotation rad, energy N mm per mm thickness (3D: N mm), wall s, crack tip and length mm, crack speed
//! mm/s, traffic B; the file's `# units:` line is made from the table ([`history::units_line`]).

/// File names of a run directory.
pub mod file {
    /// The run's identity and status (`rundir`).
    pub const RUN: &str = "run.json";
    /// The effective configuration.
    pub const CONFIG: &str = "config.toml";
    /// One row per step ([`super::history`]).
    pub const HISTORY: &str = "history.csv";
    /// The XDMF index of the point fields, for ParaView.
    pub const FIELDS_INDEX: &str = "fields.xdmf";
    /// Crack metrics over time.
    pub const CRACK: &str = "crack.json";
    /// The restart state.
    pub const CHECKPOINT: &str = "checkpoint.h5";
    /// Reaction forces over time.
    pub const FORCE_TIME: &str = "force_time.png";
    /// Reaction forces over the loading device's displacement.
    pub const FORCE_DISPLACEMENT: &str = "force_displacement.png";
    /// Crack length over time (CT runs).
    pub const CRACK_LENGTH: &str = "crack_length.png";
    /// Width of the damage bands over time (CT runs).
    pub const BAND_WIDTH: &str = "band_width.png";
    /// Crack-tip speed and crack length at every step (CT runs).
    pub const CRACK_SPEED: &str = "crack_speed.png";
    /// Prefix and suffix of the point fields of one output step, `fields_NNNNNN.h5`.
    pub const FIELDS: (&str, &str) = ("fields_", ".h5");
    /// Prefix and suffix of the damage map of one output step, `damage_NNNNNN.png`.
    pub const DAMAGE_MAP: (&str, &str) = ("damage_", ".png");

    /// The name of a numbered file (`FIELDS` or `DAMAGE_MAP`) of output step `step`.
    pub fn numbered((prefix, suffix): (&str, &str), step: usize) -> String {
        format!("{prefix}{step:06}{suffix}")
    }
}

/// Columns of `history.csv`: [`history::LEADING`], then per constraint set, rigid body and load the
/// columns of [`history::reaction_columns`], per pinned device [`history::rotation_column`], then
/// [`history::TRAILING`], in CT runs [`history::CRACK`], on several processes [`history::BYTES`] and,
/// with path following, [`history::PATH`]. Each fixed column is one [`history::Column`] of these
/// tables: its name in the header and its value in every row come from the same entry.
pub mod history {
    use crate::solver::StepReport;
    use std::fmt::Write as _;

    /// Time reached (s).
    pub const TIME: &str = "time";
    /// Attempts of the step (1 + retries with the fallback solver or a smaller dt).
    pub const ATTEMPTS: &str = "attempts";
    /// Newton iterations.
    pub const NEWTON_ITS: &str = "newton_its";
    /// Linear iterations.
    pub const LINEAR_ITS: &str = "linear_its";
    /// Unknowns of the step.
    pub const UNKNOWNS: &str = "unknowns";
    /// Wall time of the step's set-up (s).
    pub const WALL_SETUP: &str = "wall_setup";
    /// Wall time of the assembly, inside the solve (s).
    pub const WALL_ASSEMBLY: &str = "wall_assembly";
    /// Wall time of the converged attempt's solve (s).
    pub const WALL_SOLVE: &str = "wall_solve";
    /// Wall time of the step with its failed attempts (s).
    pub const WALL_TOTAL: &str = "wall_total";
    /// 1 if the PETSc objects were built anew for the step.
    pub const NEW_PATTERN: &str = "new_pattern";

    /// One cell of a history row, with the way it is written.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub enum Cell<'a> {
        /// A count or flag, written as an integer.
        Count(u64),
        /// A number in scientific notation with this many digits after the point (`{:.9e}`).
        Number(f64, usize),
        /// A name.
        Text(&'a str),
        /// No value (a step of an older checkpoint without a crack front or a path point).
        Empty,
    }

    impl Cell<'_> {
        /// Appends the cell's text to `s`.
        pub fn write(self, s: &mut String) {
            let _ = match self {
                Self::Count(n) => write!(s, "{n}"),
                Self::Number(v, digits) => write!(s, "{v:.digits$e}"),
                Self::Text(name) => write!(s, "{name}"),
                Self::Empty => Ok(()),
            };
        }
    }

    /// A fixed column of `history.csv`.
    pub struct Column {
        /// Its name in the header (lower case, `_`-separated).
        pub name: &'static str,
        /// Unit of its values ("-": a count, flag, name, ratio or a norm of mixed units).
        pub unit: &'static str,
        /// What it holds.
        pub description: &'static str,
        /// Its cell in the row of a step.
        pub value: fn(&StepReport) -> Cell<'_>,
        /// The quantity under which the `# units:` line names its unit ("": not named there;
        /// [`units_line`]).
        pub quantity: &'static str,
    }

    impl Column {
        /// This column with its unit named in the `# units:` line as `quantity`.
        const fn in_units_line(self, quantity: &'static str) -> Self {
            Self { quantity, ..self }
        }
    }

    /// A column `name` in `unit` holding `description`, `value` per step, not named in the `# units:`
    /// line (see [`Column::in_units_line`]).
    const fn column(
        name: &'static str,
        unit: &'static str,
        description: &'static str,
        value: fn(&StepReport) -> Cell<'_>,
    ) -> Column {
        Column {
            name,
            unit,
            description,
            value,
            quantity: "",
        }
    }

    /// The energy balance `W + E_0 - K - Psi` of a step (N mm).
    fn dissipated(r: &StepReport) -> f64 {
        r.external_work + r.initial_energy - r.kinetic_energy - r.stored_energy
    }

    /// `W + E_0 - K - Psi - damage - erosion - contact` of a step (N mm; `EnergyBooks::remainder`).
    fn remainder(r: &StepReport) -> f64 {
        r.books.remainder(
            r.external_work,
            r.initial_energy,
            r.kinetic_energy,
            r.stored_energy,
        )
    }

    /// The largest of the processes' byte counts `b` (B; 0 without any).
    fn largest(b: &[u64]) -> u64 {
        b.iter().copied().max().unwrap_or(0)
    }

    /// The columns before the per-set columns.
    pub static LEADING: [Column; 10] = [
        column("step", "-", "step number", |r| Cell::Count(r.step as u64)),
        column(TIME, "s", "time reached", |r| Cell::Number(r.time, 9)).in_units_line("time"),
        column("dt", "s", "time step taken", |r| Cell::Number(r.dt, 6)).in_units_line("dt"),
        column(
            ATTEMPTS,
            "-",
            "attempts of the step (1 + retries with the fallback solver or a smaller dt)",
            |r| Cell::Count(r.attempts as u64),
        ),
        column(NEWTON_ITS, "-", "Newton iterations", |r| {
            Cell::Count(r.solve.iterations as u64)
        }),
        column(LINEAR_ITS, "-", "linear iterations", |r| {
            Cell::Count(r.solve.linear_iterations as u64)
        }),
        column("reason", "-", "SNES converged reason", |r| {
            Cell::Text(&r.solve.reason_name)
        }),
        column(
            "residual_initial",
            "-",
            "first residual norm over the step's solves",
            |r| {
                Cell::Number(
                    r.solve.residual_norms.first().copied().unwrap_or(f64::NAN),
                    6,
                )
            },
        ),
        column(
            "residual_final",
            "-",
            "last residual norm over the step's solves",
            |r| {
                Cell::Number(
                    r.solve.residual_norms.last().copied().unwrap_or(f64::NAN),
                    6,
                )
            },
        ),
        column(UNKNOWNS, "-", "unknowns of the step", |r| {
            Cell::Count(r.unknowns as u64)
        }),
    ];

    /// The columns after the per-set columns.
    pub static TRAILING: [Column; 19] = [
        column(
            "contact_solves",
            "-",
            "SNES solves of the step (contact active set and pin rotations)",
            |r| Cell::Count(r.contact_solves as u64),
        ),
        column("kinetic_energy", "N mm", "kinetic energy K", |r| {
            Cell::Number(r.kinetic_energy, 9)
        }).in_units_line("energy"),
        column("stored_energy", "N mm", "stored energy Psi", |r| {
            Cell::Number(r.stored_energy, 9)
        }).in_units_line("energy"),
        column("external_work", "N mm", "external work W", |r| {
            Cell::Number(r.external_work, 9)
        }).in_units_line("energy"),
        column(
            "dissipated_energy",
            "N mm",
            "the energy balance W + E_0 - K - Psi: what damage, erosion and the time integration took out",
            |r| Cell::Number(dissipated(r), 9),
        ).in_units_line("energy"),
        column(
            "damage_dissipation",
            "N mm",
            "energy released by damage so far, the trapezoidal rule in the undamaged plane energy psi_0",
            |r| Cell::Number(r.books.damage, 9),
        ).in_units_line("energy"),
        column(
            "erosion_energy",
            "N mm",
            "stored energy of eroded points, taken out when they stopped carrying stress",
            |r| Cell::Number(r.books.erosion, 9),
        ).in_units_line("energy"),
        column(
            "contact_loss",
            "N mm",
            "kinetic energy lost at the inelastic impacts of closed contact constraints",
            |r| Cell::Number(r.books.contact, 9),
        ).in_units_line("energy"),
        column(
            "transfer_loss",
            "N mm",
            "kinetic energy the grid transfer took out: the points' less the grid's after P2G minus the \
             same after G2P, summed over the steps",
            |r| Cell::Number(r.books.transfer, 9),
        ).in_units_line("energy"),
        column(
            "energy_remainder",
            "N mm",
            "dissipated_energy - damage_dissipation - erosion_energy - contact_loss: what the grid \
             transfer and the time integration took out",
            |r| Cell::Number(remainder(r), 9),
        ).in_units_line("energy"),
        column(
            "remainder_fraction",
            "-",
            "energy_remainder over external_work (0 while there is no work)",
            |r| {
                let fraction = if r.external_work > 0.0 {
                    remainder(r) / r.external_work
                } else {
                    0.0
                };
                Cell::Number(fraction, 6)
            },
        ),
        column(
            "integration_remainder",
            "N mm",
            "energy_remainder - transfer_loss: what the time integration on the grid and the solver \
             tolerances took out",
            |r| Cell::Number(remainder(r) - r.books.transfer, 9),
        ).in_units_line("energy"),
        column(
            "law_remainder",
            "N mm",
            "the part of integration_remainder the time rule of the stresses took: their trapezoidal \
             work sum_p V^0 (P_n + P) : (F - F_n) / 2 less stored_energy, damage_dissipation and \
             erosion_energy",
            |r| {
                r.books
                    .law_remainder(r.stored_energy)
                    .map_or(Cell::Empty, |w| Cell::Number(w, 9))
            },
        ).in_units_line("energy"),
        column(
            "eroded_stress_work",
            "N mm",
            "the part of the stresses' trapezoidal work done in the step after a point eroded, by half \
             its last stress",
            |r| r.books.eroded_work.map_or(Cell::Empty, |w| Cell::Number(w, 9)),
        ).in_units_line("energy"),
        column(WALL_SETUP, "s", "wall time of the step's set-up", |r| {
            Cell::Number(r.wall_setup, 4)
        }).in_units_line("wall"),
        column(
            WALL_ASSEMBLY,
            "s",
            "wall time of the assembly (inside the solve)",
            |r| Cell::Number(r.wall_assembly, 4),
        ).in_units_line("wall"),
        column(
            WALL_SOLVE,
            "s",
            "wall time of the converged attempt's solve",
            |r| Cell::Number(r.wall_solve, 4),
        ).in_units_line("wall"),
        column(
            WALL_TOTAL,
            "s",
            "wall time of the step with its failed attempts",
            |r| Cell::Number(r.wall_total, 4),
        ).in_units_line("wall"),
        column(
            NEW_PATTERN,
            "-",
            "1 if the PETSc objects were built anew for the step",
            |r| Cell::Count(u64::from(r.new_pattern)),
        ),
    ];

    /// The crack columns after [`TRAILING`] (CT runs), empty in the rows of an older checkpoint's steps.
    pub static CRACK: [Column; 5] = [
        column(
            "crack_tip_x",
            "mm",
            "crack tip after the step: the crack point farthest from the notch tip",
            |r| r.crack.map_or(Cell::Empty, |f| Cell::Number(f.tip[0], 6)),
        ).in_units_line("crack tip and length"),
        column("crack_tip_y", "mm", "see crack_tip_x", |r| {
            r.crack.map_or(Cell::Empty, |f| Cell::Number(f.tip[1], 6))
        }).in_units_line("crack tip and length"),
        column(
            "crack_length",
            "mm",
            "crack length, the tip's distance from the notch tip",
            |r| r.crack.map_or(Cell::Empty, |f| Cell::Number(f.length, 6)),
        ).in_units_line("crack tip and length"),
        column(
            "crack_speed",
            "mm/s",
            "crack-tip speed: least-squares slope of the crack length over the last 10 us, at least 5 \
             steps (crack::tip_speed)",
            |r| r.crack.map_or(Cell::Empty, |f| Cell::Number(f.speed, 6)),
        ).in_units_line("crack speed"),
        column(
            "crack_bands",
            "-",
            "bands of the crack on the measuring ring (2 or more: branching)",
            |r| r.crack.map_or(Cell::Empty, |f| Cell::Count(f.bands as u64)),
        ),
    ];

    /// The traffic columns after the crack columns (runs on several processes).
    pub static BYTES: [Column; 2] = [
        column(
            "bytes_sent",
            "B",
            "the bytes the process that sent most sent in the step through the program's own exchanges \
             (points, nodal sums, residual rows, gathers of the unknowns; PETSc's own traffic not counted)",
            |r| Cell::Count(largest(&r.bytes_sent)),
        ),
        column(
            "bytes_unknowns",
            "B",
            "of bytes_sent, the largest process's bytes in the gathers of the unknowns for the residual \
             and Jacobian evaluations",
            |r| Cell::Count(largest(&r.bytes_unknowns)),
        ),
    ];

    /// The path-following columns, last (runs with `[path]`).
    pub static PATH: [Column; 3] = [
        column(
            "path_lambda",
            "s",
            "the load factor: the reference set has moved its velocity times it",
            |r| r.path.map_or(Cell::Empty, |p| Cell::Number(p.lambda, 9)),
        ),
        column("path_opening", "mm", "the measured opening", |r| {
            r.path.map_or(Cell::Empty, |p| Cell::Number(p.opening, 9))
        }),
        column(
            "path_ratio",
            "-",
            "the step's prescribed motion over its nominal one (< 0 on a snap-back)",
            |r| r.path.map_or(Cell::Empty, |p| Cell::Number(p.ratio, 9)),
        ),
    ];

    /// The per-set columns' quantities in the `# units:` line ([`reaction_columns`], then
    /// [`rotation_column`]): (quantity, unit, what a plate's value is).
    pub static SET_UNITS: [(&str, &str, &str); 3] = [
        ("displacement", "mm", ""),
        ("force", "N", " (3D: of the whole plate)"),
        ("rotation", "rad", ""),
    ];

    /// The `# units:` line of `history.csv` (with its newline) for a run in `dimension` (3: a plate;
    /// otherwise plane strain, where a unit of force, `N` or `N mm`, is per mm thickness): every
    /// quantity named in [`LEADING`], [`SET_UNITS`], [`TRAILING`] and [`CRACK`], once, in that order,
    /// with its unit. The path-following and traffic columns are not named in it.
    pub fn units_line(dimension: usize) -> String {
        let named = |columns: &'static [Column]| columns.iter().map(|c| (c.quantity, c.unit, ""));
        let quantities = named(&LEADING)
            .chain(SET_UNITS.iter().copied())
            .chain(named(&TRAILING))
            .chain(named(&CRACK));
        let mut seen: Vec<&str> = Vec::new();
        let mut parts: Vec<String> = Vec::new();
        for (quantity, unit, plate) in quantities {
            if quantity.is_empty() || seen.contains(&quantity) {
                continue;
            }
            seen.push(quantity);
            parts.push(match dimension {
                3 => format!("{quantity} {unit}{plate}"),
                _ if unit.starts_with('N') => format!("{quantity} {unit} per mm thickness"),
                _ => format!("{quantity} {unit}"),
            });
        }
        format!("# units: {}\n", parts.join(", "))
    }

    /// Displacement (mm) and force (N per mm thickness; in 3D N) columns of a constraint set, rigid body
    /// or load, `dimension` (2 or 3) components each.
    pub fn reaction_columns(name: &str, dimension: usize) -> Vec<String> {
        let d = dimension.min(3);
        let (u, f) = (&["ux", "uy", "uz"][..d], &["fx", "fy", "fz"][..d]);
        u.iter().chain(f).map(|c| format!("{name}_{c}")).collect()
    }

    /// Rotation column (rad) of a pinned device.
    pub fn rotation_column(name: &str) -> String {
        format!("{name}_rotation")
    }
}

#[cfg(test)]
mod tests {
    use super::history::{BYTES, CRACK, Cell, Column, LEADING, PATH, TRAILING};

    fn fixed() -> impl Iterator<Item = &'static Column> {
        [&LEADING[..], &TRAILING, &CRACK, &BYTES, &PATH]
            .into_iter()
            .flatten()
    }

    #[test]
    fn every_fixed_column_has_a_distinct_csv_safe_name_a_unit_and_a_description() {
        let mut names: Vec<&str> = fixed().map(|c| c.name).collect();
        for c in fixed() {
            let safe = c.name.bytes().all(|b| b.is_ascii_lowercase() || b == b'_');
            assert!(safe, "{}", c.name);
            assert!(
                !c.unit.is_empty() && !c.description.is_empty(),
                "{}",
                c.name
            );
        }
        let n = names.len();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), n, "a name is used twice");
    }

    #[test]
    fn the_units_line_is_the_one_history_csv_always_had() {
        assert_eq!(
            super::history::units_line(2),
            "# units: time s, dt s, displacement mm, force N per mm thickness, rotation rad, energy N mm \
             per mm thickness, wall s, crack tip and length mm, crack speed mm/s\n"
        );
        assert_eq!(
            super::history::units_line(3),
            "# units: time s, dt s, displacement mm, force N (3D: of the whole plate), rotation rad, \
             energy N mm, wall s, crack tip and length mm, crack speed mm/s\n"
        );
    }

    #[test]
    fn a_quantity_of_the_units_line_has_one_unit() {
        for c in fixed().filter(|c| !c.quantity.is_empty()) {
            let other = fixed().find(|o| o.quantity == c.quantity && o.unit != c.unit);
            assert!(
                other.is_none(),
                "{} and {:?}",
                c.name,
                other.map(|o| o.name)
            );
        }
    }

    #[test]
    fn every_fixed_column_is_documented() {
        let docs = include_str!("../docs/configuration.md");
        let section = &docs[docs.find("## Columns of `history.csv`").expect("section")..];
        for c in fixed() {
            assert!(section.contains(&format!("`{}`", c.name)), "{}", c.name);
        }
    }

    #[test]
    fn cells_are_written_as_the_history_always_wrote_them() {
        let text = |c: Cell| {
            let mut s = String::new();
            c.write(&mut s);
            s
        };
        assert_eq!(text(Cell::Number(1e-6, 9)), "1.000000000e-6");
        assert_eq!(text(Cell::Number(-40.87553504, 6)), "-4.087554e1");
        assert_eq!(text(Cell::Number(f64::NAN, 6)), "NaN");
        assert_eq!(text(Cell::Count(7722)), "7722");
        assert_eq!(
            text(Cell::Text("CONVERGED_FNORM_ABS")),
            "CONVERGED_FNORM_ABS"
        );
        assert_eq!(text(Cell::Empty), "");
    }
}
