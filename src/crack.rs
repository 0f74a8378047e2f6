//! Crack metrics from a damage field: the damage zone grown from the notch tip, its length and tip, the
//! bands it forms, their angles against the notch axis, and a classification straight / inclined /
//! branching (the paper's finding for 0.035, 1.4 and 4.3 m/s).
//!
//! Definitions (all thresholds are fields of [`CrackCriteria`] and are written with the results):
//! * a point is *cracked* when its damage is at least `damage_threshold`;
//! * the *crack* is the set of cracked points connected to the notch tip: cracked points are binned into
//!   cells of size `h`, and cells are connected through their 8 neighbours, starting from the cells within
//!   `max(seed_radius, 2 h)` of the tip (the CT run sets half the notch width plus `2 h`, so that bands
//!   leaving the notch's corners count; damage under the loading plates or at other edges is not part of
//!   it);
//! * *length* is the largest distance of a crack point from the notch tip, the *tip* is that point;
//! * *bands* are the groups of crack points on the ring `r = ring_fraction * length` (+- h) around the notch
//!   tip, split where consecutive points (sorted by polar angle) are more than `gap_degrees` apart; a band's
//!   angle is its mean polar angle against the notch axis (+x, counter-clockwise positive);
//! * classification: two or more bands -> branching; one band with |angle| <= `straight_degrees` ->
//!   straight; otherwise inclined; no crack -> none;
//! * *band width* is measured across the bands at the stations `r = f * length`, `f` in
//!   `width_stations`: the crack points within half a point spacing `s` of the circle `r` around the
//!   notch tip, sorted along the circle and split where two neighbours are more than `2 s` apart; each
//!   group is one crossing of a band, and its width is its arc extent plus one point spacing (the bands
//!   leave the notch tip roughly radially, so the circle cuts them nearly square). The median over all
//!   crossings is the reported band width, the largest one its maximum;
//! * *zone width* is the same measure for the regularised zone, the points with damage at least
//!   `zone_threshold` (0.5): on each station circle the zone's groups of points that contain a crossing of
//!   the crack, their median width. It follows the regularisation's length scale where the band width of
//!   the nearly broken core (`d >= 0.9`) follows the cell.

use nalgebra::Vector2;
use std::collections::{HashMap, HashSet, VecDeque};

/// Thresholds of the crack metrics.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct CrackCriteria {
    /// Damage at and above which a point counts as cracked.
    pub damage_threshold: f64,
    /// Radius of the ring where bands are counted, as a fraction of the crack length.
    pub ring_fraction: f64,
    /// Angular gap (degrees) that separates two bands on the ring.
    pub gap_degrees: f64,
    /// A single band within this angle (degrees) of the notch axis is straight.
    pub straight_degrees: f64,
    /// Cracks shorter than this (mm) are not classified.
    pub min_length: f64,
    /// Radii of the band-width stations as fractions of the crack length.
    pub width_stations: [f64; 3],
    /// Cracked cells within this distance of the notch tip (mm; at least `2 h`) start the crack.
    #[serde(default)]
    pub seed_radius: f64,
    /// Damage at and above which a point belongs to the regularised zone whose width is measured across
    /// the bands (`zone_width`).
    #[serde(default = "default_zone_threshold")]
    pub zone_threshold: f64,
}

/// The damage level of the regularised zone ([`CrackCriteria::zone_threshold`]).
fn default_zone_threshold() -> f64 {
    0.5
}

impl Default for CrackCriteria {
    fn default() -> Self {
        Self {
            damage_threshold: 0.9,
            ring_fraction: 0.7,
            gap_degrees: 20.0,
            straight_degrees: 15.0,
            min_length: 10.0,
            width_stations: [0.25, 0.5, 0.75],
            seed_radius: 0.0,
            zone_threshold: default_zone_threshold(),
        }
    }
}

impl CrackCriteria {
    /// The criteria of a CT run: the default thresholds, seeded within half the notch width `notch_width`
    /// plus `2 h` of the tip (mm), so that bands leaving the notch's corners belong to the crack.
    pub fn for_notch(notch_width: f64, h: f64) -> Self {
        Self {
            seed_radius: 0.5 * notch_width + 2.0 * h,
            ..Self::default()
        }
    }
}

/// One band of the crack on the measuring ring.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Band {
    /// Mean angle against the notch axis (degrees, counter-clockwise positive).
    pub angle_degrees: f64,
    /// Crack points of the band on the ring.
    pub points: usize,
}

/// One crossing of a band by a width station.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BandCrossing {
    /// Station radius around the notch tip (mm).
    pub radius: f64,
    /// Polar angle of the crossing's centre against the notch axis (degrees).
    pub angle_degrees: f64,
    /// Width of the `d >= damage_threshold` zone across the band (mm).
    pub width: f64,
}

/// Crack state at one time.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CrackState {
    /// Time (s).
    pub time: f64,
    /// Crack length from the notch tip (mm).
    pub length: f64,
    /// Crack tip position (mm).
    pub tip: [f64; 2],
    /// Bands on the measuring ring.
    pub bands: Vec<Band>,
    /// "none", "straight", "inclined" or "branching".
    pub classification: String,
    /// Band crossings at the width stations (empty for cracks shorter than `min_length`).
    #[serde(default)]
    pub crossings: Vec<BandCrossing>,
    /// Median width of the damage bands over the crossings (mm; 0 without crossings).
    #[serde(default)]
    pub band_width: f64,
    /// Largest crossing width (mm).
    #[serde(default)]
    pub band_width_max: f64,
    /// Median width of the regularised zone (`d >= zone_threshold`) across the bands at the same
    /// stations (mm; 0 without crossings).
    #[serde(default)]
    pub zone_width: f64,
    /// Energy dissipated in the whole specimen so far by microplanes under tensile and under
    /// compressive normal strain (N mm per mm of thickness; filled in by the output writer).
    #[serde(default)]
    pub dissipated: [f64; 2],
    /// Points with damage >= `damage_threshold` that gained at least half of it while their local
    /// equivalent strain was below gamma_0 (damage carried in by the nonlocal field; filled in by the
    /// output writer).
    #[serde(default)]
    pub nonlocal_points: usize,
}

impl CrackState {
    /// The angles of the bands on the measuring ring, in whole degrees, joined by `, ` (`-99, -65`);
    /// empty without bands.
    pub fn band_angles(&self) -> String {
        let angles: Vec<String> = (self.bands.iter())
            .map(|b| format!("{:.0}", b.angle_degrees))
            .collect();
        angles.join(", ")
    }
}

/// Measures the crack grown from `notch_tip` (mm) in the damage field of points at `x` (mm); `h` is the
/// cell size (mm), `spacing` the distance between neighbouring points (mm).
pub fn measure(
    x: &[Vector2<f64>],
    damage: &[f64],
    notch_tip: Vector2<f64>,
    h: f64,
    spacing: f64,
    c: &CrackCriteria,
    time: f64,
) -> CrackState {
    let mut crack = crack_points(x, damage, notch_tip, h, c);
    crack.sort_unstable();
    let (length, tip) = farthest(x, &crack, notch_tip);
    let (bands, classification) = classify(x, &crack, notch_tip, length, h, c);
    let crossings = if length < c.min_length {
        Vec::new()
    } else {
        c.width_stations
            .iter()
            .flat_map(|f| crossings(x, &crack, notch_tip, f * length, spacing))
            .collect()
    };
    let mut widths: Vec<f64> = crossings.iter().map(|b| b.width).collect();
    widths.sort_by(f64::total_cmp);
    let band_width = median(&widths);
    // The regularised zone around the same crossings.
    let zone: Vec<usize> = (0..x.len())
        .filter(|&i| damage[i] >= c.zone_threshold)
        .collect();
    let mut zone_widths: Vec<f64> = if crossings.is_empty() {
        Vec::new()
    } else {
        c.width_stations
            .iter()
            .flat_map(|f| crossings_of(x, &zone, notch_tip, f * length, spacing))
            .filter(|z| {
                let (lo, hi) = (
                    z.angle_degrees - z.half_degrees,
                    z.angle_degrees + z.half_degrees,
                );
                crossings.iter().any(|b| {
                    (b.radius - z.radius).abs() < 1e-9 && (lo..=hi).contains(&b.angle_degrees)
                })
            })
            .map(|z| z.width)
            .collect()
    };
    zone_widths.sort_by(f64::total_cmp);
    CrackState {
        time,
        length,
        tip: [tip.x, tip.y],
        bands,
        classification,
        crossings,
        band_width,
        band_width_max: widths.last().copied().unwrap_or(0.0),
        zone_width: median(&zone_widths),
        dissipated: [0.0; 2],
        nonlocal_points: 0,
    }
}

/// Time window of the crack-tip speed (s): the least-squares slope of the crack length over the steps
/// of the last 10 us ([`tip_speed`]), and over at least [`SPEED_MIN_SAMPLES`] steps.
pub const SPEED_WINDOW: f64 = 1e-5;

/// Fewest steps (samples) the crack-tip speed is fitted over ([`SPEED_WINDOW`]).
pub const SPEED_MIN_SAMPLES: usize = 5;

/// The crack front at one step: the tip of the crack, its length, the bands on the measuring ring and
/// the tip speed (the history's crack columns).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Front {
    /// Tip position, the crack point farthest from the notch tip (mm; the notch tip while there is no
    /// crack).
    pub tip: [f64; 2],
    /// Crack length, the tip's distance from the notch tip (mm).
    pub length: f64,
    /// Bands on the measuring ring (2 or more: branching).
    pub bands: usize,
    /// Tip speed (mm/s): the least-squares slope of `length` over time in the window of
    /// [`tip_speed`].
    pub speed: f64,
}

/// The crack's length (mm) and tip: the distance from the notch tip to the farthest crack point, and
/// that point (the notch tip when the crack is empty).
fn farthest(x: &[Vector2<f64>], crack: &[usize], notch_tip: Vector2<f64>) -> (f64, Vector2<f64>) {
    let (mut length, mut tip) = (0.0, notch_tip);
    for &i in crack {
        let d = (x[i] - notch_tip).norm();
        if d > length {
            length = d;
            tip = x[i];
        }
    }
    (length, tip)
}

/// The crack front (speed 0, filled in by [`tip_speed`]) of the damage field of points at `x` (mm):
/// the crack, length, tip and bands as [`measure`] defines them, without the band widths.
pub fn front(
    x: &[Vector2<f64>],
    damage: &[f64],
    notch_tip: Vector2<f64>,
    h: f64,
    c: &CrackCriteria,
) -> Front {
    let mut crack = crack_points(x, damage, notch_tip, h, c);
    crack.sort_unstable();
    let (length, tip) = farthest(x, &crack, notch_tip);
    let (bands, _) = classify(x, &crack, notch_tip, length, h, c);
    Front {
        tip: [tip.x, tip.y],
        length,
        bands: bands.len(),
        speed: 0.0,
    }
}

/// Crack-tip speed (mm/s) at the last of the samples `(time s, length mm)` (in time order): the
/// least-squares slope of the length over the samples within [`SPEED_WINDOW`] of the last one, and over
/// at least the last [`SPEED_MIN_SAMPLES`] (fewer at the start of a run); 0 from a single sample.
pub fn tip_speed(samples: &[(f64, f64)]) -> f64 {
    let Some(&(t_end, _)) = samples.last() else {
        return 0.0;
    };
    let within = samples
        .iter()
        .rev()
        .take_while(|(t, _)| t_end - t <= SPEED_WINDOW * (1.0 + 1e-9))
        .count();
    let n = within.max(SPEED_MIN_SAMPLES).min(samples.len());
    let window = &samples[samples.len() - n..];
    if n < 2 {
        return 0.0;
    }
    let (tm, lm) = window
        .iter()
        .fold((0.0, 0.0), |(a, b), (t, l)| (a + t, b + l));
    let (tm, lm) = (tm / n as f64, lm / n as f64);
    let (mut stl, mut stt) = (0.0, 0.0);
    for (t, l) in window {
        stl += (t - tm) * (l - lm);
        stt += (t - tm) * (t - tm);
    }
    if stt > 0.0 { stl / stt } else { 0.0 }
}

/// Rayleigh wave speed (mm/s) of an isotropic elastic material with bulk modulus `bulk` and shear modulus
/// `shear` (MPa) and density `density` (t/mm^3), by Viktorov's approximation
/// `c_R = c_S (0.862 + 1.14 nu)/(1 + nu)`, `c_S = sqrt(G/rho)` (within 0.5 % of the exact root for
/// `0 <= nu <= 0.5`).
pub fn rayleigh_speed(bulk: f64, shear: f64, density: f64) -> f64 {
    let nu = (3.0 * bulk - 2.0 * shear) / (2.0 * (3.0 * bulk + shear));
    (shear / density).sqrt() * (0.862 + 1.14 * nu) / (1.0 + nu)
}

/// The crack: the points with damage `>= damage_threshold` in the cells (size `h`, mm) connected to the
/// cracked cells within the seed radius of `notch_tip`, by a flood fill over the 8 neighbours of a cell.
fn crack_points(
    x: &[Vector2<f64>],
    damage: &[f64],
    notch_tip: Vector2<f64>,
    h: f64,
    c: &CrackCriteria,
) -> Vec<usize> {
    let cell = |p: &Vector2<f64>| ((p.x / h).floor() as i64, (p.y / h).floor() as i64);
    let mut cells: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    for (i, p) in x.iter().enumerate() {
        if damage[i] >= c.damage_threshold {
            cells.entry(cell(p)).or_default().push(i);
        }
    }
    // Flood fill from the cracked cells near the notch tip.
    let mut seen: HashSet<(i64, i64)> = HashSet::new();
    let mut queue: VecDeque<(i64, i64)> = VecDeque::new();
    for (&k, pts) in &cells {
        let seed = c.seed_radius.max(2.0 * h);
        if pts.iter().any(|&i| (x[i] - notch_tip).norm() <= seed) {
            seen.insert(k);
            queue.push_back(k);
        }
    }
    while let Some((i, j)) = queue.pop_front() {
        for di in -1..=1 {
            for dj in -1..=1 {
                let k = (i + di, j + dj);
                if cells.contains_key(&k) && seen.insert(k) {
                    queue.push_back(k);
                }
            }
        }
    }
    seen.iter().flat_map(|k| cells[k].iter().copied()).collect()
}

/// The bands of the crack points on the ring of radius `ring_fraction length` around `notch_tip` (angles
/// in degrees grouped at gaps over `gap_degrees`) and the classification (`none`, `straight`, `inclined`,
/// `branching`).
fn classify(
    x: &[Vector2<f64>],
    crack: &[usize],
    notch_tip: Vector2<f64>,
    length: f64,
    h: f64,
    c: &CrackCriteria,
) -> (Vec<Band>, String) {
    let mut bands = Vec::new();
    let classification = if crack.is_empty() || length < c.min_length {
        "none".to_owned()
    } else {
        let r = c.ring_fraction * length;
        let mut angles: Vec<f64> = crack
            .iter()
            .filter(|&&i| ((x[i] - notch_tip).norm() - r).abs() <= h)
            .map(|&i| {
                let d = x[i] - notch_tip;
                d.y.atan2(d.x).to_degrees()
            })
            .collect();
        angles.sort_by(f64::total_cmp);
        let mut start = 0;
        for k in 1..=angles.len() {
            if k == angles.len() || angles[k] - angles[k - 1] > c.gap_degrees {
                let group = &angles[start..k];
                if !group.is_empty() {
                    bands.push(Band {
                        angle_degrees: group.iter().sum::<f64>() / group.len() as f64,
                        points: group.len(),
                    });
                }
                start = k;
            }
        }
        match bands.as_slice() {
            [] => "none".to_owned(),
            [b] if b.angle_degrees.abs() <= c.straight_degrees => "straight".to_owned(),
            [_] => "inclined".to_owned(),
            _ => "branching".to_owned(),
        }
    };
    (bands, classification)
}

/// Width of a damage band along a line (mm): the distance between the outermost points where the
/// profile `(x, d)`, sorted by `x` (mm), crosses the damage `level`, linearly interpolated between its
/// samples; 0 if the profile never crosses it twice.
pub fn band_width_1d(profile: &[(f64, f64)], level: f64) -> f64 {
    let crossings: Vec<f64> = profile
        .windows(2)
        .filter(|w| (w[0].1 >= level) != (w[1].1 >= level))
        .map(|w| w[0].0 + (level - w[0].1) / (w[1].1 - w[0].1) * (w[1].0 - w[0].0))
        .collect();
    match crossings.as_slice() {
        [a, .., b] => b - a,
        _ => 0.0,
    }
}

/// The median of sorted `values` (0 if empty).
fn median(values: &[f64]) -> f64 {
    match values.len() {
        0 => 0.0,
        n if n % 2 == 1 => values[n / 2],
        n => 0.5 * (values[n / 2 - 1] + values[n / 2]),
    }
}

/// The crossings of the bands formed by the points `crack` with the circle of radius `r` (mm) around
/// `centre` ([`crossings_of`]).
fn crossings(
    x: &[Vector2<f64>],
    crack: &[usize],
    centre: Vector2<f64>,
    r: f64,
    spacing: f64,
) -> Vec<BandCrossing> {
    crossings_of(x, crack, centre, r, spacing)
        .into_iter()
        .map(|z| BandCrossing {
            radius: z.radius,
            angle_degrees: z.angle_degrees,
            width: z.width,
        })
        .collect()
}

/// One group of points on a station circle: a crossing with its angular half-extent.
struct Crossing {
    radius: f64,
    angle_degrees: f64,
    /// Half the angle the group spans, widened by half a point spacing on each side (degrees).
    half_degrees: f64,
    width: f64,
}

/// The groups of the points `points` (a sorted subset of `x`) within half a point spacing `spacing` of the
/// circle of radius `r` (mm) around `centre`, sorted along the circle. Two neighbours of a group more than
/// two spacings apart belong to different bands where other points of the ring lie between them, and to
/// the two faces of one opened band where none does (the gap is the crack's opening): the faces are one
/// crossing, whose width is that of its material (the extents of its runs of points, each plus one
/// spacing), without the opening.
fn crossings_of(
    x: &[Vector2<f64>],
    points: &[usize],
    centre: Vector2<f64>,
    r: f64,
    spacing: f64,
) -> Vec<Crossing> {
    // Arc length along the circle from the notch axis (+x), with membership; the cut of atan2 at +-180
    // degrees lies in the notch behind the tip, where no band runs.
    let mut ring: Vec<(f64, bool)> = (0..x.len())
        .filter_map(|i| {
            let d = x[i] - centre;
            ((d.norm() - r).abs() <= 0.5 * spacing)
                .then(|| (d.y.atan2(d.x) * r, points.binary_search(&i).is_ok()))
        })
        .collect();
    ring.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out = Vec::new();
    // The open group: its first point, the start of its current run, its last point, the width of its
    // closed runs, and whether a point outside the set lies after its last point.
    let mut group: Option<(f64, f64, f64, f64)> = None;
    let mut between = false;
    let close = |(a, run, b, w): (f64, f64, f64, f64)| Crossing {
        radius: r,
        angle_degrees: (0.5 * (a + b) / r).to_degrees(),
        half_degrees: ((0.5 * (b - a) + 0.5 * spacing) / r).to_degrees(),
        width: w + (b - run) + spacing,
    };
    for &(t, member) in &ring {
        if !member {
            between = group.is_some();
            continue;
        }
        group = Some(match group {
            None => (t, t, t, 0.0),
            Some((a, run, b, w)) if t - b <= 2.0 * spacing => (a, run, t, w),
            Some((a, run, b, w)) if !between => (a, t, t, w + (b - run) + spacing),
            Some(g) => {
                out.push(close(g));
                (t, t, t, 0.0)
            }
        });
        between = false;
    }
    out.extend(group.map(close));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on a 0.5 mm lattice over [0, 100]^2, damaged where `f` says so.
    fn field(f: impl Fn(Vector2<f64>) -> bool) -> (Vec<Vector2<f64>>, Vec<f64>) {
        let mut x = Vec::new();
        let mut d = Vec::new();
        for i in 0..200 {
            for j in 0..200 {
                let p = Vector2::new(0.25 + 0.5 * i as f64, 0.25 + 0.5 * j as f64);
                d.push(if f(p) { 1.0 } else { 0.0 });
                x.push(p);
            }
        }
        (x, d)
    }

    /// Distance of `p` from the segment from `a` at angle `deg` with length `len`.
    fn near_ray(p: Vector2<f64>, a: Vector2<f64>, deg: f64, len: f64) -> bool {
        let t = Vector2::new(deg.to_radians().cos(), deg.to_radians().sin());
        let s = (p - a).dot(&t).clamp(0.0, len);
        (p - (a + s * t)).norm() <= 1.5
    }

    const TIP: Vector2<f64> = Vector2::new(30.0, 50.0);

    #[test]
    fn tip_speed_is_the_slope_over_the_window() {
        // Constant speed 2e5 mm/s (200 m/s) in 1 us steps: exact whatever the window.
        let v = 2e5;
        let line: Vec<(f64, f64)> = (0..40)
            .map(|k| (k as f64 * 1e-6, 3.0 + v * k as f64 * 1e-6))
            .collect();
        assert!((tip_speed(&line) / v - 1.0).abs() < 1e-9);
        // A jump older than the window (and its 5 steps) does not count: only the last 10 us.
        let mut jump = line.clone();
        for s in &mut jump[..20] {
            s.1 -= 50.0;
        }
        assert!((tip_speed(&jump) / v - 1.0).abs() < 1e-9);
        // Steps of 10 us: the window still holds the last 5 samples.
        let coarse: Vec<(f64, f64)> = (0..8).map(|k| (k as f64 * 1e-5, (k * k) as f64)).collect();
        let slope = tip_speed(&coarse);
        assert!((slope - 1.0e6).abs() < 1e-3, "{slope}");
        assert_eq!(tip_speed(&line[..1]), 0.0);
        assert_eq!(tip_speed(&[]), 0.0);
    }

    #[test]
    fn rayleigh_speed_of_concrete_and_a_known_solid() {
        // nu = 0.25: the exact Rayleigh root is 0.9194 c_S; Viktorov gives 0.9176 c_S.
        let (g, rho) = (1.0, 1.0);
        let k = 2.0 * g * (1.0 + 0.25) / (3.0 * (1.0 - 2.0 * 0.25));
        assert!((rayleigh_speed(k, g, rho) / 0.9194 - 1.0).abs() < 0.005);
        // E = 30000 MPa, nu = 0.2, rho = 2.4e-9 t/mm^3: c_S = 2282 m/s, c_R = 2073 m/s.
        let (e, nu) = (30000.0, 0.2);
        let (k, g) = (e / (3.0 * (1.0 - 2.0 * nu)), e / (2.0 * (1.0 + nu)));
        let c_r = rayleigh_speed(k, g, 2.4e-9);
        assert!((c_r / 2.073e6 - 1.0).abs() < 1e-3, "{c_r}");
    }

    #[test]
    fn straight_inclined_and_branching_cracks_are_told_apart() {
        let c = CrackCriteria::default();
        let (x, d) = field(|p| near_ray(p, TIP, 0.0, 40.0));
        let s = measure(&x, &d, TIP, 1.0, 0.5, &c, 0.0);
        assert_eq!(s.classification, "straight", "{s:?}");
        assert!((s.length - 41.5).abs() < 1.0, "{s:?}");
        let (x, d) = field(|p| near_ray(p, TIP, -35.0, 40.0));
        let s = measure(&x, &d, TIP, 1.0, 0.5, &c, 0.0);
        assert_eq!(s.classification, "inclined", "{s:?}");
        assert!((s.bands[0].angle_degrees + 35.0).abs() < 3.0, "{s:?}");
        let (x, d) = field(|p| {
            near_ray(p, TIP, 0.0, 10.0)
                || near_ray(p, TIP + Vector2::new(10.0, 0.0), 30.0, 35.0)
                || near_ray(p, TIP + Vector2::new(10.0, 0.0), -30.0, 35.0)
        });
        let s = measure(&x, &d, TIP, 1.0, 0.5, &c, 0.0);
        assert_eq!(s.classification, "branching", "{s:?}");
        assert_eq!(s.bands.len(), 2, "{s:?}");
    }

    #[test]
    fn band_width_is_measured_across_the_bands() {
        let c = CrackCriteria::default();
        // Straight band 3 mm wide (|y - 50| <= 1.5) on the 0.5 mm lattice: 6 rows of points.
        let (x, d) = field(|p| p.x >= 30.0 && p.x <= 70.0 && (p.y - 50.0).abs() <= 1.5);
        let s = measure(&x, &d, TIP, 1.0, 0.5, &c, 0.0);
        assert_eq!(s.crossings.len(), 3, "{s:?}");
        assert!((s.band_width - 3.0).abs() <= 0.3, "{s:?}");
        assert!(s.crossings.iter().all(|b| b.angle_degrees.abs() < 2.0));
        // Two branches at +-30 degrees, 1.5 mm from their axis (3 mm wide): two crossings per station
        // beyond the fork, each about 3 mm wide (the circle cuts them at a small angle).
        let (x, d) = field(|p| {
            near_ray(p, TIP, 0.0, 10.0)
                || near_ray(p, TIP + Vector2::new(10.0, 0.0), 30.0, 35.0)
                || near_ray(p, TIP + Vector2::new(10.0, 0.0), -30.0, 35.0)
        });
        let s = measure(&x, &d, TIP, 1.0, 0.5, &c, 0.0);
        let far: Vec<_> = s.crossings.iter().filter(|b| b.radius > 20.0).collect();
        assert_eq!(far.len(), 4, "{s:?}");
        for b in far {
            assert!(b.width > 2.5 && b.width < 4.5, "{b:?}");
        }
        // A wider band reads wider.
        let (x, d) = field(|p| p.x >= 30.0 && p.x <= 70.0 && (p.y - 50.0).abs() <= 5.0);
        let wide = measure(&x, &d, TIP, 1.0, 0.5, &c, 0.0);
        assert!((wide.band_width - 10.0).abs() <= 0.6, "{wide:?}");
    }

    #[test]
    fn zone_width_measures_the_regularised_zone_around_the_crack_only() {
        // A core of d = 1 (|y - 50| <= 1, 2 mm wide) inside a zone of d = 0.6 (|y - 50| <= 4, 8 mm wide),
        // and a patch of d = 0.6 away from the crack that meets the stations' circles but no crossing.
        let (x, _) = field(|_| true);
        let d: Vec<f64> = (x.iter())
            .map(|p| {
                let band = p.x >= 30.0 && p.x <= 70.0;
                let zone = band && (p.y - 50.0).abs() <= 4.0;
                let patch = (p.x - 30.0).abs() <= 3.0 && p.y > 65.0 && p.y < 90.0;
                if band && (p.y - 50.0).abs() <= 1.0 {
                    1.0
                } else if zone || patch {
                    0.6
                } else {
                    0.0
                }
            })
            .collect();
        let s = measure(&x, &d, TIP, 1.0, 0.5, &CrackCriteria::default(), 0.0);
        assert!((s.band_width - 2.0).abs() <= 0.3, "{s:?}");
        assert!((s.zone_width - 8.0).abs() <= 0.6, "{s:?}");
        // A zone no wider than the core reads as the core.
        let core: Vec<f64> = d
            .iter()
            .map(|&v| if v >= 1.0 { 1.0 } else { 0.0 })
            .collect();
        let s = measure(&x, &core, TIP, 1.0, 0.5, &CrackCriteria::default(), 0.0);
        assert!((s.zone_width - s.band_width).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn an_opened_band_is_one_crossing_as_wide_as_its_material() {
        // A band 6 mm wide (|y - 50| <= 3) opened by 2 mm in its middle (no points at |y - 50| < 1): the
        // two faces are one crossing of 4 mm of material at each station, not two bands of 2 mm.
        let (x, d) = field(|p| p.x >= 30.0 && p.x <= 70.0 && (p.y - 50.0).abs() <= 3.0);
        let (x, d): (Vec<_>, Vec<_>) = (x.into_iter().zip(d))
            .filter(|(p, _)| !(p.x >= 30.0 && (p.y - 50.0).abs() < 1.0))
            .unzip();
        let s = measure(&x, &d, TIP, 1.0, 0.5, &CrackCriteria::default(), 0.0);
        assert_eq!(s.crossings.len(), 3, "{s:?}");
        assert!((s.band_width - 4.0).abs() <= 0.3, "{s:?}");
        assert!((s.zone_width - 4.0).abs() <= 0.3, "{s:?}");
        // Two bands with undamaged material between them stay two crossings.
        let (x, d) = field(|p| {
            p.x >= 30.0 && p.x <= 70.0 && (p.y - 50.0).abs() >= 2.0 && (p.y - 50.0).abs() <= 4.0
        });
        let c = CrackCriteria {
            seed_radius: 5.0,
            ..CrackCriteria::default()
        };
        let s = measure(&x, &d, TIP, 1.0, 0.5, &c, 0.0);
        assert_eq!(s.crossings.len(), 6, "{s:?}");
        assert!((s.band_width - 2.0).abs() <= 0.3, "{s:?}");
    }

    #[test]
    fn bands_leaving_the_notch_corners_are_found_with_the_seed_radius() {
        // A notch 10 mm wide: a band from its lower corner (5 mm below the tip's centre) going down.
        let corner = TIP - Vector2::new(0.0, 5.0);
        let (x, d) = field(|p| near_ray(p, corner, -80.0, 40.0));
        let near = measure(&x, &d, TIP, 1.0, 0.5, &CrackCriteria::default(), 0.0);
        assert_eq!(near.classification, "none", "{near:?}");
        let c = CrackCriteria {
            seed_radius: 5.0 + 2.0,
            ..CrackCriteria::default()
        };
        let s = measure(&x, &d, TIP, 1.0, 0.5, &c, 0.0);
        assert_eq!(s.classification, "inclined", "{s:?}");
        assert!(s.length > 40.0, "{s:?}");
    }

    #[test]
    fn damage_away_from_the_notch_tip_is_not_part_of_the_crack() {
        let c = CrackCriteria::default();
        let (x, d) = field(|p| near_ray(p, Vector2::new(5.0, 10.0), 0.0, 40.0));
        let s = measure(&x, &d, TIP, 1.0, 0.5, &c, 0.0);
        assert_eq!(s.classification, "none");
        assert_eq!(s.length, 0.0);
    }

    #[test]
    fn band_width_1d_interpolates_the_outermost_crossings() {
        let profile = [
            (0.0, 0.0),
            (1.0, 0.4),
            (2.0, 1.0),
            (3.0, 0.8),
            (4.0, 0.2),
            (5.0, 0.0),
        ];
        // 0.5 is crossed at x = 1 + 0.1/0.6 and x = 3 + 0.3/0.6.
        let w = band_width_1d(&profile, 0.5);
        assert!((w - (3.5 - (1.0 + 1.0 / 6.0))).abs() < 1e-12, "{w}");
        assert_eq!(band_width_1d(&profile, 1.5), 0.0);
    }
}
