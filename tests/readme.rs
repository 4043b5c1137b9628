//! The README and the measurement log (`docs/measurements.md`) each list every `##` and `###` heading in
//! their table of contents, in order, with the anchor GitHub gives it, and every link to a heading
//! (`](#anchor)` within a file, `](docs/measurements.md#anchor)` and `](../README.md#anchor)` between the
//! two) points at one: a renamed or moved section cannot leave a dead entry behind. The command lines of
//! both files and the binary's flags agree: every flag a `cog-gpu` command line of a code block uses is one
//! its subcommand's `--help` lists, and every flag a subcommand's `--help` lists is written in the README
//! (the usage document: a renamed or new flag cannot go unnoticed).

use std::collections::{BTreeSet, HashMap};
use std::process::Command;

fn readme() -> String {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/README.md");
    std::fs::read_to_string(path).expect("README.md beside Cargo.toml")
}

/// The measurement log the README links to.
fn measurements() -> String {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/measurements.md");
    std::fs::read_to_string(path).expect("docs/measurements.md beside Cargo.toml")
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

/// The `## Contents` list of `text` equals its `##` and `###` headings with their anchors.
fn assert_contents_lists_every_section(text: &str, file: &str) {
    let all = headings(text);
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
    assert_eq!(contents, expected, "{file}'s Contents differs from its headings");
}

#[test]
fn contents_lists_every_section_in_order() {
    assert_contents_lists_every_section(&readme(), "README.md");
    assert_contents_lists_every_section(&measurements(), "docs/measurements.md");
}

/// Every link of `text` written as `prefix` + `anchor)` names a heading of `target_text`; returns how many
/// links it checked.
fn assert_links_point_at_headings(text: &str, prefix: &str, target_text: &str, what: &str) -> usize {
    let anchors: Vec<String> = headings(target_text).into_iter().map(|h| h.2).collect();
    let mut checked = 0;
    for piece in text.split(prefix).skip(1) {
        let target = piece.split(')').next().unwrap_or_default();
        assert!(anchors.iter().any(|a| a == target), "{what} links to #{target}, which no heading has");
        checked += 1;
    }
    checked
}

#[test]
fn links_point_at_headings() {
    let (readme, log) = (readme(), measurements());
    assert_links_point_at_headings(&readme, "](#", &readme, "README.md");
    assert_links_point_at_headings(&log, "](#", &log, "docs/measurements.md");
    // The README points into the log where it moved a section's measurements; the log back at the README.
    let into_log = assert_links_point_at_headings(&readme, "](docs/measurements.md#", &log, "README.md");
    assert!(into_log >= 8, "only {into_log} links from the README into docs/measurements.md");
    assert_links_point_at_headings(&log, "](../README.md#", &readme, "docs/measurements.md");
    assert!(readme.contains("](docs/measurements.md)"), "the README names the measurement log");
}

#[test]
fn link_check_finds_a_dead_anchor() {
    let text = "## Here\n[a](#here) [b](#gone)\n";
    let caught = std::panic::catch_unwind(|| assert_links_point_at_headings(text, "](#", text, "case"));
    assert!(caught.is_err(), "a link to #gone must fail the check");
    assert_eq!(assert_links_point_at_headings("## Here\n[a](#here)\n", "](#", "## Here\n", "case"), 1);
}

/// The binary's output for `args` (stdout; it must succeed).
fn cog_gpu(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_cog-gpu")).args(args).output().expect("run cog-gpu");
    assert!(out.status.success(), "cog-gpu {args:?} failed: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("UTF-8 help")
}

/// The long flags (`--name`) a help text lists in its Options section, in order.
fn help_flags(help: &str) -> BTreeSet<String> {
    help.lines()
        .filter_map(|line| {
            let line = line.trim_start();
            let line = line.strip_prefix("-h, ").or(line.strip_prefix("-V, ")).unwrap_or(line);
            let flag = line.strip_prefix("--")?;
            let name: String = flag.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '-').collect();
            Some(format!("--{name}"))
        })
        .collect()
}

/// The subcommands `cog-gpu --help` lists (but `help`).
fn subcommands() -> Vec<String> {
    let help = cog_gpu(&["--help"]);
    let commands = help.split("Commands:").nth(1).expect("a Commands section").split("Options:").next().unwrap();
    commands
        .lines()
        .filter_map(|line| line.split_whitespace().next())
        .filter(|name| *name != "help")
        .map(str::to_string)
        .collect()
}

/// Every `cog-gpu SUBCOMMAND ...` command line of the README's code blocks (continuation lines joined,
/// `#` comments dropped), as (line number, subcommand, the flags it writes).
fn readme_command_lines(text: &str, subcommands: &[String]) -> Vec<(usize, String, Vec<String>)> {
    let mut out = Vec::new();
    let mut in_code = false;
    let lines: Vec<&str> = text.lines().collect();
    let mut n = 0;
    while n < lines.len() {
        let line = lines[n];
        n += 1;
        if line.starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if !in_code {
            continue;
        }
        let start = n;
        let mut command = line.split(" #").next().unwrap().to_string();
        while command.trim_end().ends_with('\\') && n < lines.len() {
            command = command.trim_end().trim_end_matches('\\').to_string();
            command.push(' ');
            command.push_str(lines[n].split(" #").next().unwrap());
            n += 1;
        }
        // A command line: `cog-gpu` (or a path ending in it) as a word, then the subcommand, after
        // global flags.
        let words: Vec<&str> = command.split_whitespace().collect();
        let Some(at) = words.iter().position(|w| *w == "cog-gpu" || w.ends_with("/cog-gpu")) else { continue };
        let Some(sub) = words[at + 1..].iter().find(|w| !w.starts_with('-')) else { continue };
        if !subcommands.iter().any(|s| s == sub) {
            continue;
        }
        let flags = words[at + 1..]
            .iter()
            .filter_map(|w| {
                let w = w.trim_start_matches(['[', '(']);
                let flag = w.strip_prefix("--")?;
                let name: String = flag.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '-').collect();
                (!name.is_empty()).then(|| format!("--{name}"))
            })
            .collect();
        out.push((start, sub.to_string(), flags));
    }
    out
}

#[test]
fn readme_command_lines_use_only_flags_the_binary_accepts() {
    let subcommands = subcommands();
    let global = help_flags(&cog_gpu(&["--help"]));
    let mut accepted: HashMap<String, BTreeSet<String>> = HashMap::new();
    let mut problems = Vec::new();
    for (file, text) in [("README", readme()), ("docs/measurements.md", measurements())] {
        let mut checked = 0;
        for (line, sub, flags) in readme_command_lines(&text, &subcommands) {
            let accepted = accepted.entry(sub.clone()).or_insert_with(|| help_flags(&cog_gpu(&[&sub, "--help"])));
            for flag in flags {
                checked += 1;
                if !accepted.contains(&flag) && !global.contains(&flag) {
                    problems.push(format!("{file} line {line}: `cog-gpu {sub}` has no {flag}"));
                }
            }
        }
        // The scan found each file's command lines (it cannot pass by finding none).
        assert!(checked > 100, "only {checked} flags found in {file}'s command lines");
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn every_flag_of_every_subcommand_is_in_the_readme() {
    let text = readme();
    let mut missing = Vec::new();
    for sub in subcommands() {
        for flag in help_flags(&cog_gpu(&[&sub, "--help"])) {
            // A flag counts as written when it stands as a whole word (not as the prefix of a longer one).
            let written = text.match_indices(flag.as_str()).any(|(at, _)| {
                let next = text[at + flag.len()..].chars().next();
                !next.is_some_and(|c| c.is_ascii_alphanumeric() || c == '-')
            });
            if !written && flag != "--help" {
                missing.push(format!("`cog-gpu {sub} {flag}`"));
            }
        }
    }
    assert!(missing.is_empty(), "flags the README never writes: {}", missing.join(", "));
}

#[test]
fn help_flags_reads_clap_options() {
    let help = "Options:\n      --cpu                 Force\n  -h, --help   Print help\n      --min-score <S>  x\n  -V, --version  v\n";
    let flags: Vec<String> = help_flags(help).into_iter().collect();
    assert_eq!(flags, ["--cpu", "--help", "--min-score", "--version"]);
}
