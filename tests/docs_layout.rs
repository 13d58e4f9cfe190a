//! docs/layout.md against the tree: the page that says what each file of
//! the crates does names every one of them, and names none that is gone.
//!
//! For each crate whose sources it covers (`shared/`, `rig-config/`,
//! `firmware/`, `pil/`, `host-sim/` and every `host-sim/crates/*/`), the
//! page has a `## ` section whose heading names the crate's directory in
//! backticks (`` ## `shared/` ``), and
//!
//! - every `.rs` file under the crate's `src/` appears in that section in
//!   backticks, by its path under `src/` (`` `observer/task.rs` ``), under
//!   the crate (`` `src/flash.rs` ``) or under the repository;
//! - every backticked `.rs` path in that section exists, under the crate's
//!   `src/`, under the crate or under the repository.
//!
//! The files are read from the disk, not from git, so a module added in the
//! working tree fails the test until the page names it.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("host-sim/ has a parent").to_path_buf()
}

/// The crate directories whose sources the page must cover, relative to the
/// repository, with a trailing `/` as the page writes them.
fn crate_dirs(root: &Path) -> Vec<String> {
    let mut dirs: Vec<String> =
        ["shared/", "rig-config/", "firmware/", "pil/", "host-sim/"].iter().map(|d| d.to_string()).collect();
    let mut members: Vec<String> = std::fs::read_dir(root.join("host-sim/crates"))
        .expect("host-sim/crates/ exists")
        .map(|e| e.expect("readable entry").path())
        .filter(|p| p.join("src").is_dir())
        .map(|p| format!("host-sim/crates/{}/", p.file_name().unwrap().to_string_lossy()))
        .collect();
    members.sort();
    dirs.extend(members);
    dirs
}

/// Every `.rs` file under `dir`, as paths relative to `dir` with `/`.
fn rust_files(dir: &Path) -> Vec<String> {
    fn walk(base: &Path, dir: &Path, out: &mut Vec<String>) {
        for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let path = entry.expect("readable entry").path();
            if path.is_dir() {
                walk(base, &path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let rel = path.strip_prefix(base).unwrap();
                out.push(rel.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/"));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// The page's `## ` sections: heading line and body.
fn sections(page: &str) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = Vec::new();
    let mut in_fence = false;
    for line in page.lines() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
        }
        if !in_fence && line.starts_with("## ") {
            out.push((line.to_string(), String::new()));
        } else if let Some((_, body)) = out.last_mut() {
            body.push_str(line);
            body.push('\n');
        }
    }
    out
}

/// The backticked spans of a text, line by line, fenced blocks left out.
fn code_spans(text: &str) -> BTreeSet<String> {
    let mut in_fence = false;
    let mut spans = BTreeSet::new();
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if !in_fence {
            spans.extend(line.split('`').skip(1).step_by(2).map(str::to_string));
        }
    }
    spans
}

#[test]
fn layout_page_names_every_source_file_and_no_missing_one() {
    let root = repo_root();
    let page_path = root.join("docs/layout.md");
    let page = std::fs::read_to_string(&page_path).expect("docs/layout.md is readable");
    let sections = sections(&page);
    let mut problems = Vec::new();
    for dir in crate_dirs(&root) {
        let wanted = format!("`{dir}`");
        let Some((_, body)) = sections.iter().find(|(heading, _)| heading.contains(&wanted)) else {
            problems.push(format!("no `## ` section whose heading names {wanted}"));
            continue;
        };
        let spans = code_spans(body);
        let src = root.join(&dir).join("src");
        for file in rust_files(&src) {
            let names = [file.clone(), format!("src/{file}"), format!("{dir}src/{file}")];
            if !names.iter().any(|n| spans.contains(n)) {
                problems.push(format!("{dir}src/{file} is not named in the section of {wanted}"));
            }
        }
        for span in spans.iter().filter(|s| s.ends_with(".rs") && !s.contains(char::is_whitespace) && !s.contains('$'))
        {
            let exists = [src.join(span), root.join(&dir).join(span), root.join(span)].iter().any(|p| p.is_file());
            if !exists {
                problems.push(format!("the section of {wanted} names `{span}`, which is not in the tree"));
            }
        }
    }
    assert!(problems.is_empty(), "docs/layout.md does not match the tree:\n  {}", problems.join("\n  "));
}
