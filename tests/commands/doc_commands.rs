//! The commands of README.md and docs/*.md run as written.
//!
//! Convention for the documentation (keep it when you write a page):
//!
//! - A command a reader should type goes in a fenced block opened with
//!   ```` ```sh ````, one command a line, no prompt (`$ `); a comment may end
//!   the line (`  # what it does`), and a line ending in `\` continues on the
//!   next. What a command prints goes in a ```` ```text ```` block, never in
//!   a `sh` one.
//! - A line is a `host-sim` command when it starts with `host-sim` or with
//!   `cargo run --release -p host-sim --` (a leading `time` is ignored).
//!   Every other line (`cargo build ...`, `./scripts/test.sh`, `cargo test
//!   ...`) is left alone.
//! - A `host-sim` command is SHORT when it asks for help (`--help`, `-h`, or
//!   `host-sim help ...`) or when its subcommand is in [`QUICK`]; short
//!   commands are run against the built binary and must exit with status 0.
//!   They run in a fresh directory under `std::env::temp_dir()`, so their
//!   outputs (default `out/<command>/`, or the `--out` given, which is taken
//!   relative to that directory) never land in the repository; an argument
//!   naming a file of the repository (`configs/rig.toml`) is passed as its
//!   absolute path.
//! - Every other `host-sim` command is LONG (it simulates travels for
//!   seconds to minutes, or reads a dataset an earlier command wrote): it is
//!   only checked to parse: its subcommand is one `host-sim --help` lists,
//!   and every flag it uses (`--name` or `--name=value`) is listed by
//!   `host-sim SUBCOMMAND --help`.
//!
//! A second test checks that the README's command table has a row for every
//! subcommand `host-sim --help` lists.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Subcommands that finish in about a second and need no input file: run
/// for real when a page shows them.
const QUICK: &[&str] = &["modes"];

/// A short command that runs longer than this fails the test.
const SHORT_TIMEOUT: Duration = Duration::from_secs(30);

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("host-sim/ has a parent").to_path_buf()
}

/// README.md and every docs/*.md, in a stable order.
fn doc_files() -> Vec<PathBuf> {
    let root = repo_root();
    let mut files = vec![root.join("README.md")];
    let mut pages: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/ exists")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    pages.sort();
    files.extend(pages);
    files
}

/// One command line of a ```sh block: the file and line it starts on, and
/// its text with continuations joined.
struct DocCommand {
    place: String,
    text: String,
}

fn sh_commands(file: &Path) -> Vec<DocCommand> {
    let text = std::fs::read_to_string(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let name = file.strip_prefix(repo_root()).unwrap_or(file).display().to_string();
    let mut commands = Vec::new();
    let mut in_sh = false;
    let mut in_other_fence = false;
    let mut pending: Option<DocCommand> = None;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim();
        if let Some(info) = trimmed.strip_prefix("```") {
            if in_sh {
                in_sh = false;
                assert!(pending.is_none(), "{name}:{}: a ```sh block ends inside a continued line", i + 1);
            } else if in_other_fence {
                in_other_fence = false;
            } else if info.trim() == "sh" {
                in_sh = true;
            } else {
                in_other_fence = true;
            }
            continue;
        }
        if !in_sh {
            continue;
        }
        let code = strip_comment(line);
        let code = code.trim();
        let (code, continues) = match code.strip_suffix('\\') {
            Some(head) => (head.trim_end(), true),
            None => (code, false),
        };
        let current = match pending.take() {
            Some(mut c) => {
                c.text.push(' ');
                c.text.push_str(code);
                c
            }
            None => DocCommand { place: format!("{name}:{}", i + 1), text: code.to_string() },
        };
        if continues {
            pending = Some(current);
        } else if !current.text.is_empty() {
            commands.push(current);
        }
    }
    assert!(!in_sh, "{name}: a ```sh block is not closed");
    commands
}

/// The line without a trailing `# comment` (a `#` that starts a word outside
/// quotes).
fn strip_comment(line: &str) -> &str {
    let mut quote: Option<char> = None;
    let mut previous = ' ';
    for (i, c) in line.char_indices() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None if c == '\'' || c == '"' => quote = Some(c),
            None if c == '#' && previous.is_whitespace() => return &line[..i],
            None => {}
        }
        previous = c;
    }
    line
}

/// Words of a command line: whitespace-separated, with '...' and "..."
/// quoting (no escapes, no expansion: the pages need no more).
fn words(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut word = String::new();
    let mut in_word = false;
    let mut quote: Option<char> = None;
    for c in text.chars() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => word.push(c),
            None if c == '\'' || c == '"' => {
                quote = Some(c);
                in_word = true;
            }
            None if c.is_whitespace() => {
                if in_word {
                    out.push(std::mem::take(&mut word));
                    in_word = false;
                }
            }
            None => {
                word.push(c);
                in_word = true;
            }
        }
    }
    assert!(quote.is_none(), "unclosed quote in `{text}`");
    if in_word {
        out.push(word);
    }
    out
}

/// The arguments after `host-sim` when the line is a `host-sim` command.
fn host_sim_args(text: &str) -> Option<Vec<String>> {
    let mut w = words(text);
    if w.first().is_some_and(|f| f == "time") {
        w.remove(0);
    }
    if w.first().is_some_and(|f| f == "host-sim") {
        return Some(w[1..].to_vec());
    }
    const CARGO: [&str; 6] = ["cargo", "run", "--release", "-p", "host-sim", "--"];
    if w.len() >= CARGO.len() && w.iter().zip(CARGO).all(|(a, b)| a == b) {
        return Some(w[CARGO.len()..].to_vec());
    }
    None
}

/// The subcommand: the first word that is neither a flag nor the value of
/// the global `--config FILE`.
fn subcommand(args: &[String]) -> Option<String> {
    let mut words = args.iter();
    while let Some(word) = words.next() {
        if word == "--config" {
            words.next();
        } else if !word.starts_with('-') {
            return Some(word.clone());
        }
    }
    None
}

fn is_help(args: &[String]) -> bool {
    args.iter().any(|a| a == "--help" || a == "-h") || args.first().is_some_and(|a| a == "help")
}

/// Runs the binary with `args` in `dir`, failing after [`SHORT_TIMEOUT`];
/// returns stdout and stderr, panicking with both on a non-zero exit.
fn run(place: &str, args: &[String], dir: &Path) -> String {
    let mut child = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{place}: cannot start host-sim: {e}"));
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > SHORT_TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{place}: `host-sim {}` ran longer than {SHORT_TIMEOUT:?}", args.join(" "));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(status.success(), "{place}: `host-sim {}` exited with {status}\n{stdout}\n{stderr}", args.join(" "));
    stdout + &stderr
}

/// A fresh, empty scratch directory of this test run, removed when dropped
/// (also when an assertion fails).
struct Scratch(PathBuf);

impl Scratch {
    fn new(tag: &str) -> Self {
        let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos();
        let dir = std::env::temp_dir().join(format!("host-sim-doc-commands-{}-{nanos}-{tag}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Subcommands `host-sim --help` lists (its "Commands:" section).
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| !l.trim_start().starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .filter(|c| c != "help")
        .collect()
}

/// Whether `help` lists the flag `--name` (followed by a space, `=`, `<`,
/// `,`, or the end of the line).
fn lists_flag(help: &str, flag: &str) -> bool {
    help.match_indices(flag).any(|(i, _)| {
        let next = help[i + flag.len()..].chars().next();
        let before = help[..i].chars().next_back();
        before.is_none_or(|b| b.is_whitespace() || b == ',' || b == '[')
            && next.is_none_or(|n| n.is_whitespace() || matches!(n, '=' | '<' | ',' | ']'))
    })
}

#[test]
fn commands_in_readme_and_docs_run_as_written() {
    let root = repo_root();
    let scratch_root = Scratch::new("all");
    let top_help = run("host-sim --help", &["--help".to_string()], &scratch_root.0);
    let known = subcommands(&top_help);
    assert!(known.len() >= 10, "too few subcommands parsed from --help:\n{top_help}");

    let mut sub_help: BTreeMap<String, String> = BTreeMap::new();
    let (mut ran, mut parsed, mut other) = (0, 0, 0);
    for file in doc_files() {
        for cmd in sh_commands(&file) {
            let Some(args) = host_sim_args(&cmd.text) else {
                other += 1;
                continue;
            };
            let place = &cmd.place;
            let sub = subcommand(&args);
            if let Some(sub) = &sub {
                assert!(
                    sub == "help" || known.contains(sub),
                    "{place}: `{}`: `{sub}` is not a host-sim subcommand ({})",
                    cmd.text,
                    known.join(", ")
                );
            }
            let quick = sub.as_deref().is_some_and(|s| QUICK.contains(&s));
            if is_help(&args) || quick {
                let dir = Scratch::new(&format!("{ran}"));
                let args: Vec<String> = args
                    .iter()
                    .map(|a| {
                        let in_repo = root.join(a);
                        if !a.starts_with('-') && a.contains('/') && in_repo.exists() {
                            in_repo.display().to_string()
                        } else {
                            a.clone()
                        }
                    })
                    .collect();
                run(place, &args, &dir.0);
                ran += 1;
                continue;
            }
            let sub = sub.unwrap_or_else(|| panic!("{place}: `{}` names no subcommand", cmd.text));
            let help = sub_help
                .entry(sub.clone())
                .or_insert_with(|| run(place, &[sub.clone(), "--help".to_string()], &scratch_root.0));
            for arg in args.iter().filter(|a| a.starts_with("--")) {
                let flag = arg.split('=').next().unwrap();
                assert!(lists_flag(help, flag), "{place}: `{}`: `host-sim {sub} --help` lists no `{flag}`", cmd.text);
            }
            parsed += 1;
        }
    }
    eprintln!("doc commands: {ran} run, {parsed} checked to parse, {other} other commands left alone");
    assert!(ran >= 3, "only {ran} short host-sim commands found in the ```sh blocks");
    assert!(parsed >= 10, "only {parsed} long host-sim commands found in the ```sh blocks");
}

#[test]
fn readme_command_table_lists_every_subcommand() {
    let dir = Scratch::new("table");
    let help = run("host-sim --help", &["--help".to_string()], &dir.0);
    let readme = std::fs::read_to_string(repo_root().join("README.md")).unwrap();
    for sub in subcommands(&help) {
        let row = format!("| `{sub}`");
        assert!(
            readme.lines().any(|l| l.starts_with(&row)),
            "README.md: no row starting with `{row}` in the command table"
        );
    }
}
