//! Configuration values that are one of a few keywords (`ct.load_introduction = "pin"`): one table per
//! type lists the keywords, the values they stand for and what each means, and one parser turns a
//! keyword into its value or into the error that names the key and every allowed keyword.

/// A configuration value spelled as one of a few keywords; serde reads it with
/// `#[serde(try_from = "String")]` and `choice_from_string!(Type)` (this module's macro).
pub trait Choice: Sized + Copy + 'static {
    /// The dotted key the value stands under (`ct.notch_tip`).
    const KEY: &'static str;
    /// The keywords, in the order the error lists them: keyword, value, what it means.
    const CHOICES: &'static [(&'static str, Self, &'static str)];

    /// The value of `name`, or an error naming the key, the value given and the allowed keywords.
    fn from_keyword(name: &str) -> Result<Self, String> {
        if let Some((_, value, _)) = Self::CHOICES.iter().find(|(k, _, _)| *k == name) {
            return Ok(*value);
        }
        let allowed: Vec<String> = Self::CHOICES
            .iter()
            .map(|(k, _, what)| format!("\"{k}\" ({what})"))
            .collect();
        let (last, first) = allowed.split_last().expect("a choice has keywords");
        let listed = match first {
            [] => last.clone(),
            _ => format!("{} or {last}", first.join(", ")),
        };
        Err(format!("field `{}` = \"{name}\": {listed}", Self::KEY))
    }
}

/// `impl TryFrom<String>` through [`Choice::from_keyword`], for serde's `try_from = "String"`.
macro_rules! choice_from_string {
    ($t:ty) => {
        impl TryFrom<String> for $t {
            type Error = String;

            fn try_from(name: String) -> Result<Self, String> {
                <$t as $crate::config::Choice>::from_keyword(&name)
            }
        }
    };
}
