//! TOML errors in one line, naming the key they are about.

/// The key a TOML error at byte `at` of `text` is about, as
/// `table.key` (the last `[table]` or `[[table]]` header above it, and the
/// key its line assigns), when the line assigns one.
pub(super) fn field_at(text: &str, at: usize) -> Option<String> {
    let before = text.get(..at.min(text.len()))?;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let line = text[line_start..].lines().next()?;
    let (key, _) = line.split_once('=')?;
    let key = key.trim().trim_matches('"');
    if key.is_empty() || key.starts_with('#') || key.starts_with('[') {
        return None;
    }
    let table = before[..line_start].lines().rev().find_map(|l| {
        let l = l.trim();
        l.starts_with('[').then(|| {
            l.trim_start_matches('[')
                .split(']')
                .next()
                .unwrap_or("")
                .trim()
                .to_string()
        })
    });
    Some(match table {
        Some(t) if !t.is_empty() => format!("{t}.{key}"),
        _ => key.to_string(),
    })
}

/// toml's messages span several lines with a source excerpt; keep them to one.
pub(super) fn one_line(message: &str) -> String {
    let mut parts = message.lines().map(str::trim).filter(|l| {
        !l.is_empty()
            && !l.starts_with('|')
            && !l.chars().next().is_some_and(|c| c.is_ascii_digit())
    });
    let head = parts
        .next()
        .unwrap_or("invalid TOML")
        .trim_end_matches(':')
        .to_string();
    let rest: Vec<&str> = parts.collect();
    let line = if rest.is_empty() {
        head
    } else {
        format!("{head}: {}", rest.join("; "))
    };
    plain_types(&line)
}

/// serde's names of types ("expected i64") in words ("expected an
/// integer").
fn plain_types(message: &str) -> String {
    let mut out = message.to_string();
    for (rust, plain) in [
        ("i64", "an integer"),
        ("i32", "an integer"),
        ("u64", "a whole number >= 0"),
        ("u32", "a whole number >= 0"),
        ("u16", "a whole number >= 0"),
        ("u8", "a whole number >= 0"),
        ("usize", "a whole number >= 0"),
        ("f32", "a number"),
        ("f64", "a number"),
    ] {
        out = out.replace(&format!("expected {rust}"), &format!("expected {plain}"));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_is_named_by_its_table_and_key() {
        let text = "[hair]\nstyle = \"smooth\"\n\n[light]\ndirection = [1, 0]\n";
        let at = text.find("[1, 0]").unwrap();
        assert_eq!(field_at(text, at).as_deref(), Some("light.direction"));
        let text = "[[light]]\nkind = \"point\"\n  position = [0, 1]\n";
        let at = text.find("[0, 1]").unwrap();
        assert_eq!(field_at(text, at).as_deref(), Some("light.position"));
        // A header or a line that assigns nothing names no key.
        assert_eq!(field_at("[light\n", 1), None);
        assert_eq!(field_at("width = 3", 9).as_deref(), Some("width"));
    }

    #[test]
    fn type_names_are_said_in_words() {
        assert_eq!(
            one_line("invalid type: string \"64\", expected i64"),
            "invalid type: string \"64\", expected an integer"
        );
        assert_eq!(one_line("expected f32"), "expected a number");
    }
}
