//! How every binary of the project tells a user that a command failed: one line,
//! `PROGRAM: error: ` and the cause chain joined by `: ` (docs/dev.md, "Errors").
//!
//! A cause whose message spans lines (a TOML parse error, say) is folded onto the line, and a
//! cause whose text its parent already ends with (errors that print their source themselves)
//! is given once.

use std::fmt::Display;

/// The cause chain `causes` (outermost first) as one line.
pub fn error_line<I>(causes: I) -> String
where
    I: IntoIterator,
    I::Item: Display,
{
    let mut line = String::new();
    for cause in causes {
        let text = cause
            .to_string()
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect::<Vec<_>>()
            .join(" ");
        if text.is_empty() || line.ends_with(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

#[cfg(test)]
mod tests {
    use super::error_line;

    #[test]
    fn causes_are_joined_folded_and_given_once() {
        assert_eq!(
            error_line(["reading a", "No such file"]),
            "reading a: No such file"
        );
        assert_eq!(
            error_line(["invalid config f: bad key\nin `x`\n", "bad key\nin `x`"]),
            "invalid config f: bad key in `x`"
        );
        assert_eq!(error_line(["outer", "", "inner"]), "outer: inner");
        assert_eq!(error_line(Vec::<String>::new()), "");
    }
}
