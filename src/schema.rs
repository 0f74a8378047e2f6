//! The names of a run directory's files and of the columns of `history.csv`, shared by the writers
//! (`io`, `checkpoint`, `rundir`, the `run` command) and the readers (`app::compare`, `app::study`), so
//! that a renamed column or file changes in one place.
//!
//! Units of the history columns: time and dt s, displacement mm, force N per mm thickness, rotation rad,
//! energy N mm per mm thickness, wall s.

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
/// [`history::CONTACT_SOLVES`] (if there is any set), [`history::TRAILING`], in CT runs
/// [`history::CRACK`], on several processes [`history::BYTES`] and, with path following,
/// [`history::PATH`].
pub mod history {
    /// Step number.
    pub const STEP: &str = "step";
    /// Time reached (s).
    pub const TIME: &str = "time";
    /// Time step taken (s).
    pub const DT: &str = "dt";
    /// Attempts of the step (1 + retries with the fallback solver or a smaller dt).
    pub const ATTEMPTS: &str = "attempts";
    /// Newton iterations.
    pub const NEWTON_ITS: &str = "newton_its";
    /// Linear iterations.
    pub const LINEAR_ITS: &str = "linear_its";
    /// SNES converged reason.
    pub const REASON: &str = "reason";
    /// First and last residual norm over the step's solves.
    pub const RESIDUAL_INITIAL: &str = "residual_initial";
    /// See [`RESIDUAL_INITIAL`].
    pub const RESIDUAL_FINAL: &str = "residual_final";
    /// Unknowns of the step.
    pub const UNKNOWNS: &str = "unknowns";
    /// SNES solves of the step (contact active set and pin rotations).
    pub const CONTACT_SOLVES: &str = "contact_solves";
    /// Energies (N mm per mm thickness).
    pub const KINETIC_ENERGY: &str = "kinetic_energy";
    /// See [`KINETIC_ENERGY`].
    pub const STORED_ENERGY: &str = "stored_energy";
    /// See [`KINETIC_ENERGY`].
    pub const EXTERNAL_WORK: &str = "external_work";
    /// The energy balance `W + E_0 - K - Psi` (external work, kinetic energy at t = 0, kinetic and stored
    /// energy): what damage, erosion and the time integration took out (N mm per mm thickness).
    pub const DISSIPATED_ENERGY: &str = "dissipated_energy";
    /// Energy released by damage so far, the trapezoidal rule in the undamaged plane energy `psi_0`
    /// (N mm per mm thickness; `model::EnergyBooks::damage`).
    pub const DAMAGE_DISSIPATION: &str = "damage_dissipation";
    /// Stored energy of eroded points, taken out when they stopped carrying stress (N mm per mm
    /// thickness).
    pub const EROSION_ENERGY: &str = "erosion_energy";
    /// Kinetic energy lost at the inelastic impacts of closed contact constraints (N mm per mm
    /// thickness).
    pub const CONTACT_LOSS: &str = "contact_loss";
    /// Kinetic energy the grid transfer took out: the points' kinetic energy less the grid's after P2G
    /// minus the same after G2P, summed over the steps (N mm per mm thickness; `model::EnergyBooks::transfer`).
    pub const TRANSFER_LOSS: &str = "transfer_loss";
    /// `dissipated_energy - damage_dissipation - erosion_energy - contact_loss`: what the grid transfer and
    /// the time integration took out (N mm per mm thickness).
    pub const ENERGY_REMAINDER: &str = "energy_remainder";
    /// [`ENERGY_REMAINDER`] as a fraction of [`EXTERNAL_WORK`] (0 while there is no work).
    pub const REMAINDER_FRACTION: &str = "remainder_fraction";
    /// `energy_remainder - transfer_loss`: what the time integration on the grid and the solver
    /// tolerances took out (N mm per mm thickness).
    pub const INTEGRATION_REMAINDER: &str = "integration_remainder";
    /// Wall time of the step's phases (s): set-up, assembly (inside the solve), solve of the converged
    /// attempt, and the total of the step with its failed attempts.
    pub const WALL_SETUP: &str = "wall_setup";
    /// See [`WALL_SETUP`].
    pub const WALL_ASSEMBLY: &str = "wall_assembly";
    /// See [`WALL_SETUP`].
    pub const WALL_SOLVE: &str = "wall_solve";
    /// See [`WALL_SETUP`].
    pub const WALL_TOTAL: &str = "wall_total";
    /// 1 if the PETSc objects were built anew for the step.
    pub const NEW_PATTERN: &str = "new_pattern";

    /// Crack tip after the step (CT runs; mm): the crack point farthest from the notch tip.
    pub const CRACK_TIP_X: &str = "crack_tip_x";
    /// See [`CRACK_TIP_X`].
    pub const CRACK_TIP_Y: &str = "crack_tip_y";
    /// Crack length, the tip's distance from the notch tip (mm).
    pub const CRACK_LENGTH: &str = "crack_length";
    /// Crack-tip speed (mm/s): least-squares slope of the crack length over the last 10 us, at least 5
    /// steps (`crack::tip_speed`).
    pub const CRACK_SPEED: &str = "crack_speed";
    /// Bands of the crack on the measuring ring (2 or more: branching).
    pub const CRACK_BANDS: &str = "crack_bands";

    /// Path following: the load factor (s), the reference set having moved its velocity times it.
    pub const PATH_LAMBDA: &str = "path_lambda";
    /// Path following: the measured opening (mm).
    pub const PATH_OPENING: &str = "path_opening";
    /// Path following: the step's prescribed motion over its nominal one (< 0 on a snap-back).
    pub const PATH_RATIO: &str = "path_ratio";

    /// Several processes: the bytes (B) the process that sent most sent in the step through the
    /// program's own exchanges (points, nodal sums, residual rows, gathers of the unknowns; PETSc's own
    /// traffic not counted).
    pub const BYTES_SENT: &str = "bytes_sent";
    /// Several processes: of [`BYTES_SENT`], the largest process's bytes in the gathers of the unknowns
    /// for the residual and Jacobian evaluations.
    pub const BYTES_UNKNOWNS: &str = "bytes_unknowns";
    /// The traffic columns after the crack columns (runs on several processes).
    pub const BYTES: [&str; 2] = [BYTES_SENT, BYTES_UNKNOWNS];

    /// The path-following columns, last (runs with `[path]`).
    pub const PATH: [&str; 3] = [PATH_LAMBDA, PATH_OPENING, PATH_RATIO];

    /// The crack columns after [`TRAILING`] (CT runs).
    pub const CRACK: [&str; 5] = [
        CRACK_TIP_X,
        CRACK_TIP_Y,
        CRACK_LENGTH,
        CRACK_SPEED,
        CRACK_BANDS,
    ];

    /// The columns before the reactions.
    pub const LEADING: [&str; 10] = [
        STEP,
        TIME,
        DT,
        ATTEMPTS,
        NEWTON_ITS,
        LINEAR_ITS,
        REASON,
        RESIDUAL_INITIAL,
        RESIDUAL_FINAL,
        UNKNOWNS,
    ];

    /// The columns after the reactions.
    pub const TRAILING: [&str; 16] = [
        KINETIC_ENERGY,
        STORED_ENERGY,
        EXTERNAL_WORK,
        DISSIPATED_ENERGY,
        DAMAGE_DISSIPATION,
        EROSION_ENERGY,
        CONTACT_LOSS,
        TRANSFER_LOSS,
        ENERGY_REMAINDER,
        REMAINDER_FRACTION,
        INTEGRATION_REMAINDER,
        WALL_SETUP,
        WALL_ASSEMBLY,
        WALL_SOLVE,
        WALL_TOTAL,
        NEW_PATTERN,
    ];

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
