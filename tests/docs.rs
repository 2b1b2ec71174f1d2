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

/// Every `wisplight` command the docs show, as a user would paste it: the
/// lines of the code blocks of README.md, ARCHITECTURE.md, deploy/ and
/// docs/ that start with `wisplight ` (continued over `\` line ends,
/// comments cut), and the inline code spans that do, except synopses
/// (`[OPTIONAL]`, `A|B`, `...`). Each with where it is.
fn documented_commands() -> Vec<(String, Vec<String>)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = vec![
        root.join("README.md"),
        root.join("ARCHITECTURE.md"),
        root.join("deploy/README.md"),
    ];
    for e in std::fs::read_dir(root.join("docs")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") {
            files.push(p);
        }
    }
    files.sort();
    let mut out = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let name = f.strip_prefix(root).unwrap().display().to_string();
        let mut in_block = false;
        let mut pending: Option<(usize, String)> = None;
        // Prose, its lines joined, with where each line starts: inline
        // spans run over line ends.
        let mut prose = String::new();
        let mut starts: Vec<(usize, usize)> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("```") {
                in_block = !in_block;
                continue;
            }
            if !in_block {
                starts.push((prose.len(), i + 1));
                prose.push_str(line);
                prose.push(' ');
                continue;
            }
            let l = line.trim_start().trim_start_matches("$ ");
            let (at, mut cmd) = match pending.take() {
                Some((at, c)) => (at, c + " " + l.trim()),
                None if l.starts_with("wisplight ") => (i + 1, l.to_string()),
                None => continue,
            };
            if cmd.ends_with('\\') {
                cmd.pop();
                pending = Some((at, cmd));
                continue;
            }
            // Run in the background: the command is what comes before.
            let cmd = cmd.trim_end().trim_end_matches('&').to_string();
            out.push((format!("{name}:{at}"), words(&cmd)));
        }
        let mut offset = 0;
        for (k, span) in prose.split('`').enumerate() {
            let line = starts
                .iter()
                .take_while(|(start, _)| *start <= offset)
                .last()
                .map_or(1, |(_, l)| *l);
            offset += span.len() + 1;
            let span = span.split_whitespace().collect::<Vec<_>>().join(" ");
            // A synopsis, or a command named in passing (`wisplight certs`).
            let synopsis = ["[", "|", "...", "<"].iter().any(|s| span.contains(s))
                || span.split(' ').count() <= 2;
            if k % 2 == 1 && span.starts_with("wisplight ") && !synopsis {
                out.push((format!("{name}:{line}"), words(&span)));
            }
        }
    }
    out
}

/// A command line's words as a POSIX shell splits them (quotes and
/// backslashes), up to a `#` comment.
fn words(line: &str) -> Vec<String> {
    let (mut out, mut word, mut quote, mut any) = (Vec::new(), String::new(), None, false);
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match (quote, c) {
            (None, '#') if !any => break,
            (None, c) if c.is_whitespace() => {
                if any {
                    out.push(std::mem::take(&mut word));
                    any = false;
                }
            }
            (None, '\'' | '"') => {
                quote = Some(c);
                any = true;
            }
            (Some(q), c) if c == q => quote = None,
            (None | Some('"'), '\\') => {
                word.extend(chars.next());
                any = true;
            }
            (_, c) => {
                word.push(c);
                any = true;
            }
        }
    }
    if any {
        out.push(word);
    }
    out
}

#[test]
fn every_command_the_docs_show_parses_as_written() {
    use clap::Parser;
    let commands = documented_commands();
    assert!(
        commands.len() > 30,
        "only {} commands found",
        commands.len()
    );
    let mut wrong = Vec::new();
    for (at, args) in &commands {
        let parsed = if args.get(1).is_some_and(|a| a == "bench") {
            let rest =
                std::iter::once("wisplight bench".to_string()).chain(args[2..].iter().cloned());
            wisplight_cli::bench::Cli::try_parse_from(rest).map(|_| ())
        } else {
            wisplight_cli::cli::Cli::try_parse_from(args).map(|_| ())
        };
        use clap::error::ErrorKind;
        if let Err(e) = parsed
            && !matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion)
        {
            let first = e.to_string().lines().next().unwrap_or_default().to_string();
            wrong.push(format!("{at}: `{}`: {first}", args.join(" ")));
        }
    }
    assert!(
        wrong.is_empty(),
        "{} of {} documented commands do not parse:\n{}",
        wrong.len(),
        commands.len(),
        wrong.join("\n")
    );
}

#[test]
fn the_docs_command_reader_splits_as_a_shell_does() {
    assert_eq!(
        words(r#"wisplight render "a b.toml" -o 'x y.png' c\ d # a comment"#),
        ["wisplight", "render", "a b.toml", "-o", "x y.png", "c d"]
    );
}

/// Every `wisplight render ... -o docs/NAME` command the docs show
/// ([`documented_commands`]): its arguments but the output, and NAME.
fn picture_commands() -> Vec<(Vec<String>, String)> {
    let mut out: Vec<(Vec<String>, String)> = documented_commands()
        .into_iter()
        .filter_map(|(_, words)| {
            let args = &words[1..];
            let o = args.iter().position(|a| a == "-o")?;
            let target = args.get(o + 1)?.strip_prefix("docs/")?.to_string();
            let rest = args[..o].iter().chain(&args[o + 2..]).cloned().collect();
            (args.first()? == "render").then_some((rest, target))
        })
        .collect();
    out.sort();
    out.dedup();
    out
}

#[test]
fn every_doc_picture_is_what_its_command_makes() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let commands = picture_commands();
    let names: Vec<&str> = commands.iter().map(|(_, t)| t.as_str()).collect();
    for expected in [
        "render.png",
        "render-no-shadow.png",
        "light-point.png",
        "dance.gif",
    ] {
        assert!(
            names.contains(&expected),
            "{expected} not found among {names:?}"
        );
    }
    let dir = std::env::temp_dir().join(format!("wisplight-docs-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (args, target) in &commands {
        let made = dir.join(target);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_wisplight"))
            .current_dir(root)
            .args(args)
            .arg("-o")
            .arg(&made)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let committed = std::fs::read(root.join("docs").join(target)).unwrap();
        assert!(
            std::fs::read(&made).unwrap() == committed,
            "docs/{target} is not what `wisplight {} -o docs/{target}` makes now: run \
             docs/make-pictures, look at the pictures, commit them",
            args.join(" ")
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
