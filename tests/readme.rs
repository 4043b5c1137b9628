//! The README's table of contents lists every `##` and `###` heading, in order, with the anchor GitHub
//! gives it, and every in-page link (`](#anchor)`) points at a heading: a renamed section cannot leave a
//! dead entry behind.

use std::collections::HashMap;

fn readme() -> String {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/README.md");
    std::fs::read_to_string(path).expect("README.md beside Cargo.toml")
}

/// GitHub's anchor of a heading: lower case; letters, digits, `_`, `-` and spaces kept, everything else
/// dropped; spaces become `-`.
fn slug(title: &str) -> String {
    title
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, '_' | '-' | ' '))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// `(level, title, anchor)` of every heading outside code blocks, in order; a repeated anchor gets `-1`,
/// `-2`, … as on GitHub.
fn headings(text: &str) -> Vec<(usize, String, String)> {
    let mut seen: HashMap<String, usize> = HashMap::new();
    let mut in_code = false;
    let mut out = Vec::new();
    for line in text.lines() {
        if line.starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if in_code || !line.starts_with('#') {
            continue;
        }
        let level = line.chars().take_while(|&c| c == '#').count();
        let Some(title) = line[level..].strip_prefix(' ') else { continue };
        let base = slug(title);
        let count = seen.entry(base.clone()).or_insert(0);
        let anchor = if *count == 0 { base.clone() } else { format!("{base}-{count}") };
        *count += 1;
        out.push((level, title.to_string(), anchor));
    }
    out
}

#[test]
fn slug_follows_githubs_rule() {
    // Hand-made anchors of three of the README's headings.
    assert_eq!(slug("Diagnosis: `cog-gpu eval --diagnose`"), "diagnosis-cog-gpu-eval---diagnose");
    assert_eq!(
        slug("Preprocessing (`features::preprocess`, paper §3.1–3.2)"),
        "preprocessing-featurespreprocess-paper-3132"
    );
    assert_eq!(slug("Model files (`src/model.rs`)"), "model-files-srcmodelrs");
    let twice = headings("## Commands\n### Commands\n```\n## not a heading\n```\n");
    assert_eq!(twice.iter().map(|h| h.2.as_str()).collect::<Vec<_>>(), ["commands", "commands-1"]);
}

#[test]
fn contents_lists_every_section_in_order() {
    let text = readme();
    let all = headings(&text);
    let contents: Vec<&str> = text
        .split("## Contents\n")
        .nth(1)
        .expect("a `## Contents` section")
        .lines()
        .skip_while(|l| l.is_empty())
        .take_while(|l| !l.is_empty())
        .collect();
    let expected: Vec<String> = all
        .iter()
        .filter(|(level, title, _)| (2..=3).contains(level) && title != "Contents")
        .map(|(level, title, anchor)| format!("{}- [{title}](#{anchor})", "  ".repeat(level - 2)))
        .collect();
    assert_eq!(contents, expected, "README's Contents differs from its headings");
}

#[test]
fn in_page_links_point_at_headings() {
    let text = readme();
    let anchors: Vec<String> = headings(&text).into_iter().map(|h| h.2).collect();
    for piece in text.split("](#").skip(1) {
        let target = piece.split(')').next().unwrap_or_default();
        assert!(anchors.iter().any(|a| a == target), "README links to #{target}, which no heading has");
    }
}
