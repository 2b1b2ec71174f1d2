//! The scene reference in docs/scene.md against the parser: every key the
//! parser accepts is documented there, and every key documented there is
//! one the parser accepts, so that the two cannot drift apart.

use std::collections::BTreeSet;
use std::path::Path;

use engine::Scene;

/// `(table, key)` pairs of the reference's TOML block: keys set or shown
/// commented out (`# key = ...`), under the table header (`[t]`, `[[t]]`,
/// or a commented `# [[t]]`) they follow. Tables alone are `(table, "")`.
fn documented() -> BTreeSet<(String, String)> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/scene.md");
    let text = std::fs::read_to_string(&path).unwrap();
    let start = text
        .find("```toml\n")
        .expect("a TOML block in docs/scene.md")
        + 8;
    let block = &text[start..start + text[start..].find("```").unwrap()];
    let mut out = BTreeSet::new();
    let mut table = String::new();
    for line in block.lines() {
        let l = line.trim_start_matches('#').trim();
        if let Some(h) = l.strip_prefix('[') {
            let name = h.trim_start_matches('[');
            table = name[..name.find(']').unwrap()].to_string();
            out.insert((table.clone(), String::new()));
            continue;
        }
        // `key = value`, the key a bare TOML key.
        let Some((key, _)) = l.split_once(" = ") else {
            continue;
        };
        if !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            out.insert((table.clone(), key.to_string()));
        }
    }
    out
}

/// The keys the parser accepts in `table` ("" for the top level), from
/// the error it gives for a key it does not know: "unknown field `x`,
/// expected one of `a`, `b`, ..." (or "expected `a`").
fn accepted(table: &str) -> BTreeSet<String> {
    let text = match table {
        "" => "zz_not_a_key = 1\n".to_string(),
        "light" | "body" => format!("[[{table}]]\nzz_not_a_key = 1\n"),
        "animation.key" => {
            "[animation]\nmotion = \"keyframes\"\n[[animation.key]]\nzz_not_a_key = 1\n".into()
        }
        t => format!("[{t}]\nzz_not_a_key = 1\n"),
    };
    let e = Scene::from_toml_str(&text, Path::new("probe.toml"))
        .unwrap_err()
        .to_string();
    let list = e
        .split_once("expected ")
        .unwrap_or_else(|| panic!("[{table}]: no list of keys in {e:?}"))
        .1;
    list.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

#[test]
fn every_scene_key_is_documented_and_every_documented_key_is_accepted() {
    let docs = documented();
    let tables: BTreeSet<String> = docs.iter().map(|(t, _)| t.clone()).collect();
    let top = accepted("");
    assert!(top.len() >= 13, "the parser's tables: {top:?}");
    for t in &top {
        assert!(
            tables.contains(t),
            "[{t}] is not documented in docs/scene.md"
        );
    }
    for t in &tables {
        let root = t.split('.').next().unwrap();
        assert!(
            top.contains(root),
            "docs/scene.md documents [{t}], which the parser refuses"
        );
        let keys = accepted(t);
        let documented: BTreeSet<String> = docs
            .iter()
            .filter(|(dt, k)| dt == t && !k.is_empty())
            .map(|(_, k)| k.clone())
            .collect();
        for k in &keys {
            // A table within a table is documented as its own header.
            let nested = format!("{t}.{k}");
            assert!(
                documented.contains(k) || tables.contains(&nested),
                "{t}.{k} is accepted but not documented in docs/scene.md"
            );
        }
        for k in &documented {
            assert!(
                keys.contains(k),
                "docs/scene.md documents {t}.{k}, which the parser refuses"
            );
        }
    }
}
