//! The model's side of path following (`[path]`, `docs/theory.md`): the control as a run's parameters
//! carry it ([`PathControl`], a field of [`Parameters`]) and the gauge [`Model::new`](super::Model::new)
//! derives from it at t = 0 ([`Gauge`]: the two measured material points and the constraint set whose
//! motion measures the load factor), after checking that the run can be path-controlled. The step that
//! follows the path, the opening's row and the bordered Newton, is `src/solver/path.rs`, which reads the
//! gauge from the model. Units: mm, s.

use super::Parameters;
use crate::boundary::Motion;
use crate::input::BadValue;
use crate::particles::Particles;
use nalgebra::SVector;

/// Indirect displacement control of a quasi-static run: every step opens the distance between two
/// material points along `direction` by `increment`; the prescribed motion of the moving constraint
/// sets (node boxes and glued rigid bodies with a nonzero velocity) follows as the load factor.
#[derive(Debug, Clone, PartialEq)]
pub struct PathControl<const D: usize = 2> {
    /// Where the first measured point is at t = 0 (mm): the material point nearest it is measured.
    pub from: SVector<f64, D>,
    /// Where the second measured point is at t = 0 (mm).
    pub to: SVector<f64, D>,
    /// Direction of the measured opening (unit vector): `w = n . ((x_to - x_from) - (X_to - X_from))`.
    pub direction: SVector<f64, D>,
    /// Opening per step of the nominal `time.dt` (mm); a step halved on failure opens half as much.
    pub increment: f64,
}

/// The measured points of a path-controlled run and the set whose motion measures the load factor,
/// fixed when the model is built ([`Gauge::new`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Gauge<const D: usize = 2> {
    /// Ids of the measured material points (`from`, `to`).
    pub ids: [u64; 2],
    /// Unit direction of the opening.
    pub direction: SVector<f64, D>,
    /// `n . (X_to - X_from)` at t = 0 (mm).
    pub initial: f64,
    /// Opening per step of the nominal dt (mm).
    pub increment: f64,
    /// The load factor's reference: (constraint set in report order, component, velocity in mm/s); the
    /// load factor `lambda` (s) is the set's accumulated displacement over its velocity.
    pub reference: (usize, usize, f64),
}

/// The key of the configuration's path-following table in error messages.
const KEY: &str = "path";

impl<const D: usize> Gauge<D> {
    /// The gauge of `control` on the points `particles` at t = 0 with the run's `params`: the material
    /// point nearest each of `from` and `to` (the lower index on a tie). Refused: a dynamic run, applied
    /// loads, a moving set with a rise time or in contact, no moving set, an end outside the bodies
    /// (`gauge_point`), one point for both ends, a zero direction or an increment that is not > 0.
    pub fn new(
        control: &PathControl<D>,
        params: &Parameters<D>,
        particles: &Particles<D>,
    ) -> Result<Self, BadValue> {
        let bad = |value: String, allowed: &str| BadValue::new(KEY, value, allowed);
        if !params.time.quasi_static {
            return Err(bad(
                "a dynamic run".into(),
                "path following in a quasi-static run only (time.quasi_static = true)",
            ));
        }
        if let Some(l) = params.loads.first() {
            return Err(bad(
                format!("with the load `{}`", l.name),
                "no [[load]] with path following: drive the specimen by a moving [[constraint]] or \
                 glued [[rigid_body]] (their motion is what the control scales)",
            ));
        }
        let reference = moving_reference(params)?;
        let n = control.direction.norm();
        if !(n.is_finite() && n > 0.0) {
            return Err(bad(
                format!("direction {:?}", control.direction.as_slice()),
                "a nonzero direction of the opening",
            ));
        }
        if !(control.increment.is_finite() && control.increment > 0.0 && control.increment < 1e3) {
            return Err(bad(
                format!("increment {}", crate::input::shown(control.increment)),
                "an opening per step > 0 and below 1000 (mm)",
            ));
        }
        let h = params.grid.cell_size();
        let a = gauge_point("path.from", &control.from, particles, h)?;
        let b = gauge_point("path.to", &control.to, particles, h)?;
        if a == b {
            return Err(bad(
                format!(
                    "from {:?} and to {:?}",
                    control.from.as_slice(),
                    control.to.as_slice()
                ),
                "two points whose nearest material points differ (the opening is measured between them)",
            ));
        }
        let direction = control.direction / n;
        Ok(Self {
            ids: [particles.id[a], particles.id[b]],
            direction,
            initial: direction.dot(&(particles.x[b] - particles.x[a])),
            increment: control.increment,
            reference,
        })
    }
}

/// The material point nearest `target` (mm; the lower index on a tie), the end `key` of a gauge on a
/// grid of cell size `h` (mm). Refused when that point is more than one cell away: a point in a body or
/// on its boundary has a material point within half a point spacing per axis (at most `h / 2`, so
/// `sqrt(D) h / 2 < h`), and a point farther off would silently measure another place of the body.
fn gauge_point<const D: usize>(
    key: &str,
    target: &SVector<f64, D>,
    particles: &Particles<D>,
    h: f64,
) -> Result<usize, BadValue> {
    let distance = |p: usize| (particles.x[p] - target).norm();
    let nearest = (0..particles.len())
        .min_by(|&p, &q| distance(p).total_cmp(&distance(q)).then(p.cmp(&q)))
        .ok_or_else(|| BadValue::new(KEY, "no material points", "a run with material points"))?;
    let d = distance(nearest);
    if d <= h {
        return Ok(nearest);
    }
    let at: Vec<String> = particles.x[nearest]
        .iter()
        .map(|v| format!("{v:.3}"))
        .collect();
    Err(BadValue::new(
        key,
        format!("{:?} mm", target.as_slice()),
        format!(
            "a point in a body or within one cell (grid.cell_size = {h} mm) of a material point (the \
             nearest is {d:.3} mm away at ({})): the opening is measured between the material points \
             nearest `from` and `to`",
            at.join(", ")
        ),
    ))
}

/// The first moving component of the constraint sets (boxes, then rigid bodies): (set, component,
/// velocity); every moving set must start at once (no rise time) and not be a device in contact.
fn moving_reference<const D: usize>(
    params: &Parameters<D>,
) -> Result<(usize, usize, f64), BadValue> {
    let sets = params
        .boxes
        .iter()
        .map(|b| (&b.name, b.motion, b.rise_time, false))
        .chain(
            params
                .rigid
                .iter()
                .map(|r| (&r.name, r.motion, r.rise_time, r.contact.is_some())),
        );
    let mut reference = None;
    for (k, (name, motion, rise, contact)) in sets.enumerate() {
        let moving = motion.iter().enumerate().find_map(|(c, m)| match m {
            Motion::Velocity(v) if *v != 0.0 => Some((c, *v)),
            _ => None,
        });
        let Some((c, v)) = moving else { continue };
        if rise > 0.0 || contact {
            return Err(BadValue::new(
                KEY,
                format!("with the moving set `{name}`"),
                "moving constraints and glued rigid bodies without a rise time (rise_time = 0) and no \
                 moving device in contact: path following scales their motion",
            ));
        }
        reference.get_or_insert((k, c, v));
    }
    reference.ok_or_else(|| {
        BadValue::new(
            KEY,
            "without a moving set".to_string(),
            "a [[constraint]] or glued [[rigid_body]] with a nonzero velocity: its motion is the load \
             that the control scales",
        )
    })
}
