//! Bounds on a USD layer checked before the USD reader sees it: the
//! reader (openusd) parses text by recursion and composes a stage by
//! walking every path, so a layer nested thousands deep would overflow
//! the stack (an abort, not an error) or take minutes. A groom is a few
//! levels deep.

/// The deepest a layer may nest: prims, and brackets in text.
pub(super) const MAX_NESTING: usize = 64;
/// The most paths a binary crate may declare (prims and properties): a
/// groom's curves are a handful of prims. Checked before the reader
/// allocates them.
pub(super) const MAX_CRATE_PATHS: u64 = 1 << 20;

/// Checks the layer `bytes` (text or a binary crate; a `.usdz` package
/// is checked layer by layer) against the bounds; the error says which.
pub(super) fn check_layer(bytes: &[u8]) -> Result<(), String> {
    if bytes.starts_with(b"PXR-USDC") {
        check_crate(bytes)
    } else if bytes.starts_with(b"PK") {
        Ok(())
    } else {
        check_text(bytes)
    }
}

/// Text: the depth of `{`, `(` and `[` outside strings and comments.
fn check_text(b: &[u8]) -> Result<(), String> {
    let (mut depth, mut i) = (0usize, 0usize);
    while i < b.len() {
        match b[i] {
            b'#' => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
            }
            q @ (b'"' | b'\'') => {
                // A string, single or triple quoted, with escapes.
                let triple = b[i..].starts_with(&[q, q, q]);
                i += if triple { 3 } else { 1 };
                while i < b.len() {
                    if b[i] == b'\\' {
                        i += 2;
                        continue;
                    }
                    if triple && b[i..].starts_with(&[q, q, q]) {
                        i += 2;
                        break;
                    }
                    if !triple && b[i] == q {
                        break;
                    }
                    i += 1;
                }
            }
            b'{' | b'(' | b'[' => {
                depth += 1;
                if depth > MAX_NESTING {
                    return Err(format!(
                        "nested deeper than {MAX_NESTING} at byte {i} (no groom nests so deep)"
                    ));
                }
            }
            b'}' | b')' | b']' => depth = depth.saturating_sub(1),
            _ => {}
        }
        i += 1;
    }
    Ok(())
}

/// A binary crate: its version, the paths its PATHS section declares
/// (read from the table of contents before anything is allocated for
/// them), then how deep its prims nest.
fn check_crate(b: &[u8]) -> Result<(), String> {
    let u64_at = |at: usize| -> Option<u64> {
        b.get(at..at.checked_add(8)?)
            .map(|s| u64::from_le_bytes(s.try_into().expect("8 bytes")))
    };
    let truncated = || "a crate shorter than its header says (truncated?)".to_owned();
    let (major, minor) = (b.get(8).copied(), b.get(9).copied());
    if (major, minor) < (Some(0), Some(4)) {
        return Err(format!(
            "a crate of version {}.{}, older than the 0.4 the reader reads: save it again with a current USD",
            major.unwrap_or(0),
            minor.unwrap_or(0)
        ));
    }
    let toc = usize::try_from(u64_at(16).ok_or_else(truncated)?).map_err(|_| truncated())?;
    let sections = u64_at(toc).ok_or_else(truncated)?.min(64) as usize;
    for s in 0..sections {
        let at = toc + 8 + 32 * s;
        let name = b.get(at..at + 16).ok_or_else(truncated)?;
        if name.starts_with(b"PATHS\0") {
            let start =
                usize::try_from(u64_at(at + 16).ok_or_else(truncated)?).map_err(|_| truncated())?;
            let paths = u64_at(start).ok_or_else(truncated)?;
            if paths > MAX_CRATE_PATHS {
                return Err(format!(
                    "a crate of {paths} paths, more than the {MAX_CRATE_PATHS} read (a groom is a few prims: export its curves alone)"
                ));
            }
        }
    }
    use openusd::sdf::AbstractData;
    let data = openusd::usdc::CrateData::open(std::io::Cursor::new(b), true)
        .map_err(|e| format!("{e:#}"))?;
    let deepest = data
        .spec_paths()
        .iter()
        .map(|p| {
            p.as_str()
                .split('.')
                .next()
                .unwrap_or("")
                .matches('/')
                .count()
        })
        .max()
        .unwrap_or(0);
    if deepest > MAX_NESTING {
        return Err(format!(
            "prims nested {deepest} deep, more than the {MAX_NESTING} read (no groom nests so deep)"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_nesting_is_counted_outside_strings_and_comments() {
        let deep = |n: usize| "{".repeat(n) + &"}".repeat(n);
        assert!(check_text(deep(MAX_NESTING).as_bytes()).is_ok());
        let e = check_text(deep(MAX_NESTING + 1).as_bytes()).unwrap_err();
        assert!(e.contains("nested deeper than 64"), "{e}");
        // Brackets in strings, triple-quoted strings and comments do not count.
        let quoted = format!(
            "\"{}\" '''{}''' # {}\n\"a \\\" {}\"",
            "{".repeat(100),
            "(".repeat(100),
            "[".repeat(100),
            "{".repeat(100)
        );
        assert!(check_text(quoted.as_bytes()).is_ok());
    }
}
