//! `[ct]`: the compact tension specimen generator's section, its keyword values and its checks.

use super::choice::Choice;
use super::{
    Check, ConfigError, DENSITY_ALLOWED, SPEED_MAX, TIME_ALLOWED, density_ok, shown, time_ok,
};
use crate::input::serde_defaults;
use crate::material::{ElasticConfig, Material, MaterialConfig};
use serde::Deserialize;

/// How the CT specimen is loaded (`[ct] load_introduction`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(try_from = "String")]
pub enum LoadIntroduction {
    /// Rigid plates glued to the notch faces: every grid node under a plate follows it (pulls as well as
    /// pushes; the plates do not turn).
    #[default]
    Glued,
    /// Rigid plates in unilateral contact with the notch faces (push only, Coulomb friction), translating
    /// without rotation.
    Contact,
    /// Rigid plates in unilateral contact, each driven at a pin and free to turn about it (a testing
    /// machine's clevis and pin; the support is a pinned seat).
    Pin,
    /// Deformable steel inserts on the notch faces, each a body with its own velocity field in
    /// frictionless contact with the concrete, pushed by a pin-driven plate (a testing machine's
    /// loading device).
    Inserts,
}

impl Choice for LoadIntroduction {
    const KEY: &'static str = "ct.load_introduction";
    const CHOICES: &'static [(&'static str, Self, &'static str)] = &[
        ("glued", Self::Glued, "plates glued to the notch faces"),
        (
            "contact",
            Self::Contact,
            "plates pushing through unilateral contact",
        ),
        (
            "pin",
            Self::Pin,
            "contact plates turning freely about a pin",
        ),
        (
            "inserts",
            Self::Inserts,
            "steel inserts in contact with the concrete, pushed by pinned plates",
        ),
    ];
}

choice_from_string!(LoadIntroduction);

/// The end of the CT notch (`[ct] notch_tip`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(try_from = "String")]
pub enum NotchTip {
    /// A square end at `x = notch_length` with two corners (the source paper's rectangular notch).
    #[default]
    Flat,
    /// A semicircular end of radius `notch_width / 2` whose apex lies at `x = notch_length` (a sawn notch).
    Round,
}

impl Choice for NotchTip {
    const KEY: &'static str = "ct.notch_tip";
    const CHOICES: &'static [(&'static str, Self, &'static str)] = &[
        ("flat", Self::Flat, "square end with two corners"),
        (
            "round",
            Self::Round,
            "semicircular end of radius notch_width / 2, apex at notch_length",
        ),
    ];
}

choice_from_string!(NotchTip);

/// `[ct]`: the compact tension specimen of the source paper (spec 03-ct-test.md; the defaults are the
/// project's reconstruction). A plate with a straight notch from the left edge along mid-height; a rigid
/// loading plate on the lower notch face near the mouth moves down at `loading_rate`; a rigid support plate
/// holds the upper face (or moves up at the same rate with `symmetric = true`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CtSection {
    /// Plate width (mm).
    #[serde(default = "ct_width")]
    pub width: f64,
    /// Plate height (mm).
    #[serde(default = "ct_height")]
    pub height: f64,
    /// Notch length from the left edge (mm).
    #[serde(default = "ct_notch_length")]
    pub notch_length: f64,
    /// Notch width (mm), centred on mid-height.
    #[serde(default = "ct_notch_width")]
    pub notch_width: f64,
    /// End of the notch: "flat" (default, square with two corners) or "round" (semicircle of radius
    /// `notch_width / 2`, apex at `notch_length`).
    #[serde(default)]
    pub notch_tip: NotchTip,
    /// x range of the loading and support plates on the notch faces (mm).
    #[serde(default = "ct_load_zone")]
    pub load_zone: [f64; 2],
    /// Thickness of the rigid plates inside the notch (mm).
    #[serde(default = "ct_plate_thickness")]
    pub plate_thickness: f64,
    /// Opening rate of the loading plate (mm/s), e.g. 4300 for 4.3 m/s.
    pub loading_rate: f64,
    /// The loading velocity rises linearly from zero over this time (s); default 0 (a velocity step).
    #[serde(default)]
    pub rise_time: f64,
    /// Load both faces symmetrically (each at half the rate, mirror-identical devices) instead of holding
    /// the upper one.
    #[serde(default)]
    pub symmetric: bool,
    /// How the plates act on the notch faces: "glued" (default), "contact", "pin" or "inserts".
    #[serde(default)]
    pub load_introduction: LoadIntroduction,
    /// Coulomb friction coefficient between the plates and what they push (-): the concrete for
    /// "contact" and "pin", the inserts for "inserts" (whose contact with the concrete is frictionless);
    /// default 0 (frictionless).
    #[serde(default)]
    pub friction: f64,
    /// x range of the support plate on the upper notch face (mm); default: `load_zone`.
    #[serde(default)]
    pub support_zone: Option<[f64; 2]>,
    /// x of the pins of both plates (mm), for "pin" and "inserts"; default: the middle of each plate.
    #[serde(default)]
    pub pin_x: Option<f64>,
    /// Distance of the pins from the plates' contact faces into the plates (mm), for "pin" and
    /// "inserts"; default:
    /// half the plate thickness.
    #[serde(default)]
    pub pin_offset: Option<f64>,
    /// Thickness of the steel inserts on the notch faces (mm), for "inserts"; at least one cell, and
    /// the two inserts and plates leave a cell free in the notch.
    #[serde(default)]
    pub insert_thickness: Option<f64>,
    /// Constitutive law of the inserts; default: steel as neo-Hooke, E = 210,000 MPa, nu = 0.3.
    #[serde(default = "ct_insert_material")]
    pub insert_material: MaterialConfig,
    /// Density of the inserts (t/mm^3); default 7.85e-9 (steel).
    #[serde(default = "ct_insert_density")]
    pub insert_density: f64,
    /// Density of the concrete (t/mm^3).
    #[serde(default = "ct_density")]
    pub density: f64,
    /// Constitutive law of the concrete.
    pub material: MaterialConfig,
}

impl CtSection {
    /// Where the straight notch faces end (mm): `notch_length`, less the radius of a round tip.
    pub fn straight_faces_end(&self) -> f64 {
        match self.notch_tip {
            NotchTip::Flat => self.notch_length,
            NotchTip::Round => self.notch_length - 0.5 * self.notch_width,
        }
    }
}

serde_defaults! {
    ct_width: f64 = 200.0;
    ct_height: f64 = 200.0;
    ct_notch_length: f64 = 110.0;
    ct_notch_width: f64 = 10.0;
    ct_load_zone: [f64; 2] = [0.0, 30.0];
    ct_plate_thickness: f64 = 2.0;
    ct_density: f64 = 2.4e-9;
    ct_insert_density: f64 = 7.85e-9;
}

fn ct_insert_material() -> MaterialConfig {
    MaterialConfig::NeoHookean(ElasticConfig {
        youngs_modulus: Some(210_000.0),
        poisson_ratio: Some(0.3),
        ..ElasticConfig::default()
    })
}

/// The checks of `[ct]`, in the order their errors are reported.
impl CtSection {
    /// Checks the section and returns the materials of the concrete and of the inserts (with
    /// `load_introduction = "inserts"`); `h` is the grid's cell size (mm).
    pub(super) fn validate(
        &self,
        c: Check,
        h: f64,
    ) -> Result<(Material, Option<Material>), ConfigError> {
        self.validate_notch(c)?;
        self.validate_plates(c)?;
        let insert = self.validate_inserts(c, h)?;
        if !density_ok(self.density) {
            return Err(c.bad("ct.density", shown(self.density), DENSITY_ALLOWED));
        }
        if !(self.loading_rate > 0.0 && self.loading_rate <= SPEED_MAX) {
            return Err(c.bad(
                "ct.loading_rate",
                shown(self.loading_rate),
                "an opening rate > 0 and at most 1e7 mm/s (10 km/s); the direction is fixed by the \
                 set-up (the loading plate moves down, away from the upper notch face)",
            ));
        }
        if !time_ok(self.rise_time) {
            return Err(c.bad("ct.rise_time", shown(self.rise_time), TIME_ALLOWED));
        }
        let concrete = self
            .material
            .build()
            .map_err(|e| c.material("ct.material", &e))?;
        Ok((concrete, insert))
    }

    /// The plate, the notch and the zones on its faces where the plates bear.
    fn validate_notch(&self, c: Check) -> Result<(), ConfigError> {
        for (field, v) in [("ct.width", self.width), ("ct.height", self.height)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(c.bad(field, shown(v), "a length > 0 (mm)"));
            }
        }
        if !(self.notch_length > 0.0 && self.notch_length < self.width) {
            return Err(c.bad(
                "ct.notch_length",
                shown(self.notch_length),
                "0 < notch_length < width (mm)",
            ));
        }
        if !(self.notch_width > 0.0 && self.notch_width < self.height) {
            return Err(c.bad(
                "ct.notch_width",
                shown(self.notch_width),
                "0 < notch_width < height (mm)",
            ));
        }
        if self.notch_tip == NotchTip::Round && self.notch_length <= 0.5 * self.notch_width {
            return Err(c.bad(
                "ct.notch_length",
                shown(self.notch_length),
                "notch_length > notch_width / 2 with notch_tip = \"round\" (mm)",
            ));
        }
        // The plates bear on the straight faces, which end where a round tip begins.
        let end = self.straight_faces_end();
        let on_faces = |[a, b]: [f64; 2]| a >= 0.0 && a < b && b <= end;
        if !on_faces(self.load_zone) {
            return Err(c.bad(
                "ct.load_zone",
                format!("{:?}", self.load_zone),
                &format!(
                    "an x range [a, b] on the straight notch faces: 0 <= a < b <= notch_length \
                     (less notch_width / 2 with a round tip), here {end} (mm)"
                ),
            ));
        }
        if let Some(z) = self.support_zone
            && !on_faces(z)
        {
            return Err(c.bad(
                "ct.support_zone",
                format!("{z:?}"),
                &format!(
                    "an x range [a, b] on the straight upper notch face: 0 <= a < b <= \
                     notch_length (less notch_width / 2 with a round tip), here {end} (mm)"
                ),
            ));
        }
        Ok(())
    }

    /// The rigid plates: friction, pins and thickness.
    fn validate_plates(&self, c: Check) -> Result<(), ConfigError> {
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return Err(c.bad(
                "ct.friction",
                shown(self.friction),
                "a Coulomb coefficient >= 0 (0 = frictionless)",
            ));
        }
        let pinned = matches!(
            self.load_introduction,
            LoadIntroduction::Pin | LoadIntroduction::Inserts
        );
        if !pinned && (self.pin_x.is_some() || self.pin_offset.is_some()) {
            return Err(c.bad(
                "ct.pin_x/pin_offset",
                format!("{:?}/{:?}", self.pin_x, self.pin_offset),
                "only with load_introduction = \"pin\" or \"inserts\"",
            ));
        }
        if self.load_introduction == LoadIntroduction::Glued && self.friction != 0.0 {
            return Err(c.bad(
                "ct.friction",
                shown(self.friction),
                "only with load_introduction = \"contact\", \"pin\" or \"inserts\" (glued plates do \
                 not slide)",
            ));
        }
        if let Some(px) = self.pin_x {
            let [a, b] = self.load_zone;
            let s = self.support_zone.unwrap_or(self.load_zone);
            if !(px > a.max(s[0]) && px < b.min(s[1])) {
                return Err(c.bad(
                    "ct.pin_x",
                    shown(px),
                    "an x strictly inside both plates (load_zone and support_zone, mm): a massless \
                     plate pinned outside its contact face cannot balance its moment and overturns",
                ));
            }
        }
        if let Some(o) = self.pin_offset
            && !(o.is_finite() && o >= 0.0)
        {
            return Err(c.bad(
                "ct.pin_offset",
                shown(o),
                "a distance >= 0 from the contact face into the plate (mm)",
            ));
        }
        if !(self.plate_thickness > 0.0 && 2.0 * self.plate_thickness < self.notch_width) {
            return Err(c.bad(
                "ct.plate_thickness",
                shown(self.plate_thickness),
                "0 < plate_thickness < notch_width / 2 (mm)",
            ));
        }
        Ok(())
    }

    /// The steel inserts of `load_introduction = "inserts"` (and their absence otherwise), with their
    /// material; `h` is the cell size (mm).
    fn validate_inserts(&self, c: Check, h: f64) -> Result<Option<Material>, ConfigError> {
        let inserts = self.load_introduction == LoadIntroduction::Inserts;
        match (inserts, self.insert_thickness) {
            (false, Some(ti)) => {
                return Err(c.bad(
                    "ct.insert_thickness",
                    shown(ti),
                    "only with load_introduction = \"inserts\"",
                ));
            }
            (true, None) => {
                return Err(c.bad(
                    "ct.insert_thickness",
                    "(missing)".into(),
                    "the thickness of the steel inserts (mm), required with load_introduction = \
                     \"inserts\"",
                ));
            }
            (true, Some(ti)) => {
                let room = self.notch_width - 2.0 * (ti + self.plate_thickness);
                if !(ti >= h - 1e-9 && room >= h - 1e-9) {
                    return Err(c.bad(
                        "ct.insert_thickness",
                        shown(ti),
                        &format!(
                            "at least one cell ({h} mm), with a cell left free between the two \
                             inserts and their plates: notch_width - 2 (insert_thickness + \
                             plate_thickness) >= cell_size (mm); here {room} mm"
                        ),
                    ));
                }
            }
            (false, None) => {}
        }
        if !inserts {
            return Ok(None);
        }
        if !density_ok(self.insert_density) {
            return Err(c.bad(
                "ct.insert_density",
                shown(self.insert_density),
                DENSITY_ALLOWED,
            ));
        }
        let steel = self
            .insert_material
            .build()
            .map_err(|e| c.material("ct.insert_material", &e))?;
        Ok(Some(steel))
    }
}
