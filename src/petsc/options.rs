//! PETSc's options database: programmatic defaults that the command line overrides, and the list of
//! options nobody used (misspelled options are otherwise silently ignored by PETSc).

use super::{Result, SessionGuard, check, cstring, sys};
use std::ffi::{CStr, c_char};

/// Sets `-name value` (or a flag when `value` is `None`) in the global options database, overriding any
/// previous value, including one from the command line.
pub fn set_option(_s: &SessionGuard, name: &str, value: Option<&str>) -> Result<()> {
    let n = cstring(&dashed(name))?;
    let v = value.map(cstring).transpose()?;
    // SAFETY: PETSc copies both strings.
    check(
        unsafe {
            sys::PetscOptionsSetValue(
                std::ptr::null_mut(),
                n.as_ptr(),
                v.as_ref().map_or(std::ptr::null(), |v| v.as_ptr()),
            )
        },
        "PetscOptionsSetValue",
    )
}

/// Removes `-name` from the global options database (PETSc's own default applies again).
pub fn clear_option(_s: &SessionGuard, name: &str) -> Result<()> {
    let n = cstring(&dashed(name))?;
    // SAFETY: PETSc reads the name during the call.
    check(
        unsafe { sys::PetscOptionsClearValue(std::ptr::null_mut(), n.as_ptr()) },
        "PetscOptionsClearValue",
    )
}

/// True if `-name` is present in the options database.
pub fn has_option(_s: &SessionGuard, name: &str) -> Result<bool> {
    let n = cstring(&dashed(name))?;
    let mut set = sys::PetscBool_PETSC_FALSE;
    // SAFETY: out-parameter only.
    check(
        unsafe {
            sys::PetscOptionsHasName(std::ptr::null_mut(), std::ptr::null(), n.as_ptr(), &mut set)
        },
        "PetscOptionsHasName",
    )?;
    Ok(set == sys::PetscBool_PETSC_TRUE)
}

/// The value of `-name` if it is set (an empty string for a flag without value).
pub fn option_string(_s: &SessionGuard, name: &str) -> Result<Option<String>> {
    let n = cstring(&dashed(name))?;
    let mut buf = [0 as c_char; 512];
    let mut set = sys::PetscBool_PETSC_FALSE;
    // SAFETY: buf is writable for its length; PETSc NUL-terminates.
    check(
        unsafe {
            sys::PetscOptionsGetString(
                std::ptr::null_mut(),
                std::ptr::null(),
                n.as_ptr(),
                buf.as_mut_ptr(),
                buf.len(),
                &mut set,
            )
        },
        "PetscOptionsGetString",
    )?;
    if set != sys::PetscBool_PETSC_TRUE {
        return Ok(None);
    }
    // SAFETY: NUL-terminated by PETSc within buf.
    Ok(Some(
        unsafe { CStr::from_ptr(buf.as_ptr()) }
            .to_string_lossy()
            .into_owned(),
    ))
}

/// Sets `-name value` only if the user did not give `-name` (so the command line always wins).
pub fn set_default_option(s: &SessionGuard, name: &str, value: Option<&str>) -> Result<()> {
    if has_option(s, name)? {
        return Ok(());
    }
    set_option(s, name, value)
}

/// Applies a string of options such as `"-ksp_type preonly -pc_type lu"` as defaults: each option is set
/// unless already present (typically from the command line). Returns the options that were applied.
pub fn apply_default_options(
    s: &SessionGuard,
    options: &str,
) -> Result<Vec<(String, Option<String>)>> {
    let mut applied = Vec::new();
    for (name, value) in parse_options(options) {
        if !has_option(s, &name)? {
            set_option(s, &name, value.as_deref())?;
            applied.push((name, value));
        }
    }
    Ok(applied)
}

/// Splits an options string into (name, value) pairs. A token starting with `-` followed by a letter is
/// a name; a following token that is not a name is its value (so negative numbers are values).
pub(crate) fn parse_options(options: &str) -> Vec<(String, Option<String>)> {
    let is_name = |t: &str| {
        t.starts_with('-')
            && t[1..]
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_alphabetic())
    };
    let tokens: Vec<&str> = options.split_whitespace().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < tokens.len() {
        let t = tokens[i];
        if is_name(t) {
            let value = tokens
                .get(i + 1)
                .filter(|v| !is_name(v))
                .map(|v| v.to_string());
            i += if value.is_some() { 2 } else { 1 };
            out.push((t.trim_start_matches('-').to_owned(), value));
        } else {
            i += 1;
        }
    }
    out
}

/// Options in the database that no PETSc object has queried so far (typically misspelled ones).
pub fn unused_options(_s: &SessionGuard) -> Result<Vec<String>> {
    let mut n = 0;
    let mut names: *mut *mut c_char = std::ptr::null_mut();
    let mut values: *mut *mut c_char = std::ptr::null_mut();
    // SAFETY: PETSc allocates the arrays; restored below.
    check(
        unsafe { sys::PetscOptionsLeftGet(std::ptr::null_mut(), &mut n, &mut names, &mut values) },
        "PetscOptionsLeftGet",
    )?;
    let mut out = Vec::with_capacity(n as usize);
    for i in 0..n as usize {
        // SAFETY: names has n valid NUL-terminated entries.
        let name = unsafe { CStr::from_ptr(*names.add(i)) }
            .to_string_lossy()
            .into_owned();
        out.push(format!("-{name}"));
    }
    // SAFETY: returns the arrays obtained above.
    check(
        unsafe {
            sys::PetscOptionsLeftRestore(std::ptr::null_mut(), &mut n, &mut names, &mut values)
        },
        "PetscOptionsLeftRestore",
    )?;
    Ok(out)
}

fn dashed(name: &str) -> String {
    format!("-{}", name.trim_start_matches('-'))
}

#[cfg(test)]
mod tests {
    use super::parse_options;

    #[test]
    fn options_string_is_split_into_names_and_values() {
        let got = parse_options("-ksp_type preonly -snes_monitor -snes_rtol 1e-8 -x -1.5");
        let want = vec![
            ("ksp_type".to_owned(), Some("preonly".to_owned())),
            ("snes_monitor".to_owned(), None),
            ("snes_rtol".to_owned(), Some("1e-8".to_owned())),
            ("x".to_owned(), Some("-1.5".to_owned())),
        ];
        assert_eq!(got, want);
    }
}
