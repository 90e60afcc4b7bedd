//! The one rule for every plan name that becomes a path or a script token: the plan's name,
//! dataset names, method (variant) names and sweep values.
//!
//! A name is 1 to [`MAX_NAME`] characters of `A-Z a-z 0-9 . _ + -`, and does not start with `.`
//! or `-` (no hidden folder, no `..`, nothing read as a flag). A sweep value sits inside a folder
//! name (`METHOD@flag=VALUE`), so it may start with `-` or `.` (`-0.5`) but uses the same
//! characters. Two names are the same when they are equal ignoring ASCII case (one folder on a
//! case-insensitive file system); two sweep values also when they are the same number (`5`,
//! `5.0`, `5e0`).

/// Longest name, in characters.
pub const MAX_NAME: usize = 64;

fn allowed(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '+' | '-')
}

fn check_chars(s: &str) -> Result<(), String> {
    if s.is_empty() {
        return Err("is empty".into());
    }
    if s.chars().count() > MAX_NAME {
        return Err(format!(
            "is {} characters long (at most {MAX_NAME})",
            s.chars().count()
        ));
    }
    if let Some(c) = s.chars().find(|&c| !allowed(c)) {
        return Err(format!(
            "contains {c:?}: use only letters, digits and . _ + - (the name becomes a folder \
             and a script token)"
        ));
    }
    Ok(())
}

/// Check a plan, dataset or method name; the error says what is wrong (without the name).
pub fn check(s: &str) -> Result<(), String> {
    check_chars(s)?;
    if s.starts_with(['.', '-']) {
        return Err("must not start with `.` or `-`".into());
    }
    Ok(())
}

/// Check a sweep value (see the module header).
pub fn check_value(s: &str) -> Result<(), String> {
    check_chars(s)
}

/// The form two names are compared in.
pub fn normalise(s: &str) -> String {
    s.to_ascii_lowercase()
}

/// The form two sweep values are compared in: a number's value, else the lowercase text.
pub fn normalise_value(s: &str) -> String {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => format!("{v:e}"),
        _ => normalise(s),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_rule() {
        for ok in ["ct-crop", "unispine", "a", "X.1_b+c", &"n".repeat(MAX_NAME)] {
            assert!(check(ok).is_ok(), "{ok}");
        }
        for bad in [
            "",
            ".",
            "..",
            ".hidden",
            "-flag",
            "a/b",
            "../x",
            "/abs",
            "a b",
            "a\nb",
            "a\0b",
            "<script>",
            "a'b",
            "a\"b",
            "$(x)",
            "é",
            &"n".repeat(MAX_NAME + 1),
        ] {
            assert!(check(bad).is_err(), "{bad:?}");
        }
        assert!(check_value("-0.5").is_ok());
        assert!(
            check_value("..").is_ok(),
            "inside a folder name, `..` is plain text"
        );
        assert!(check_value("a/b").is_err());
        assert!(check_value("").is_err());
    }

    #[test]
    fn duplicates_are_found_after_normalisation() {
        assert_eq!(normalise("CT"), normalise("ct"));
        assert_eq!(normalise_value("5"), normalise_value("5.0"));
        assert_eq!(normalise_value("5"), normalise_value("5e0"));
        assert_ne!(normalise_value("5"), normalise_value("50"));
        assert_eq!(normalise_value("Rirf"), normalise_value("rirf"));
        // Only finite numbers compare by value: `inf` and `infinity` are two texts (two
        // folders), though both parse as the same infinite number.
        assert_ne!(normalise_value("inf"), normalise_value("infinity"));
        assert_eq!(normalise_value("INF"), normalise_value("inf"));
    }
}
