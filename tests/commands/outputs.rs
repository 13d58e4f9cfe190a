//! Where the commands write: never into their own inputs, a run's files as
//! a whole or not at all (also when interrupted), no staging directory left
//! for ever, a `compare --merge` that takes each case once.

use std::fs;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use super::bad_input::{host_sim, run_err, run_ok, s};

/// Every file under `dir` with its contents, sorted by path.
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                files.push((path.strip_prefix(dir).unwrap().display().to_string(), fs::read(&path).unwrap()));
            }
        }
    }
    files.sort();
    files
}

fn staging_dirs(dir: &Path) -> Vec<String> {
    fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".host-sim-partial-"))
        .collect()
}

#[test]
fn an_output_directory_inside_the_input_dataset_is_refused_even_with_force() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    run_ok(&["travel", "--quiet", "--m-car", "45.5", "--lw-start", "3", "--lw-end", "4", "--out", s(&data)]);
    let before = snapshot(&data);
    for (args, out) in [
        (vec!["analyze", s(&data)], data.clone()),
        (vec!["analyze", s(&data)], data.join("results")),
        (vec!["analyze", s(&data)], data.join("..").join("data")),
        // Before: `identify DATASET --out DATASET --force` overwrote a
        // recording named `free_decays` with its results table.
        (vec!["identify", s(&data)], data.clone()),
        (vec!["gap", s(&data)], data.join("gap")),
    ] {
        let mut args = args.clone();
        args.extend(["--force", "--out", s(&out)]);
        let err = run_err(&args);
        assert!(err.contains("inside the input") && err.contains("another --out"), "{args:?}: {err}");
        assert_eq!(snapshot(&data), before, "{args:?} changed the input dataset");
    }
}

#[test]
fn an_output_that_is_a_file_is_named_as_such() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("results");
    fs::write(&file, "mine").unwrap();
    let err = run_err(&["modes", "--out", s(&file)]);
    assert!(err.contains("is a file") && err.contains("expected a directory"), "{err}");
    assert_eq!(fs::read_to_string(&file).unwrap(), "mine");
}

#[test]
fn a_staging_directory_left_by_a_killed_run_is_removed_by_the_next_run() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("modes");
    // Process id 4 294 967 295 exceeds every system's maximum: that run has ended.
    let stale = out.join(".host-sim-partial-4294967295-0");
    fs::create_dir_all(&stale).unwrap();
    fs::write(stale.join("modes.csv"), vec![b'x'; 4096]).unwrap();
    run_ok(&["modes", "--out", s(&out)]);
    if Path::new("/proc/self").exists() {
        assert!(staging_dirs(&out).is_empty(), "{:?}", staging_dirs(&out));
    }
    assert!(out.join("modes.csv").is_file());
}

/// Sends `signal` to `host-sim args` once it has run for `after`; returns
/// its exit status, or `None` if it finished first.
#[cfg(unix)]
fn interrupt(args: &[&str], signal: &str, after: Duration) -> Option<std::process::ExitStatus> {
    let mut child = host_sim().args(args).stdout(std::process::Stdio::null()).spawn().unwrap();
    let started = Instant::now();
    while started.elapsed() < after {
        if child.try_wait().unwrap().is_some() {
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = Command::new("kill").args([signal, &child.id().to_string()]).status().unwrap();
    assert!(status.success(), "kill {signal} failed");
    Some(child.wait().unwrap())
}

#[cfg(unix)]
#[test]
fn an_interrupted_forced_run_leaves_the_earlier_outputs_whole_and_no_staging_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let args = ["dataset", "--seed", "1", "--out", s(&data)];
    let started = Instant::now();
    run_ok(&args);
    // The same work again is interrupted a third of the way through.
    let after = started.elapsed() / 3;
    let before = snapshot(&data);
    assert!(before.len() >= 4, "{}", before.len());
    // Another seed over it, with --force, interrupted while it simulates.
    for signal in ["-INT", "-TERM"] {
        let forced = ["dataset", "--seed", "2", "--force", "--out", s(&data)];
        let Some(status) = interrupt(&forced, signal, after) else {
            panic!("`dataset` finished within {after:?}: the interruption was not tried");
        };
        assert!(!status.success(), "{signal}: an interrupted run reported success");
        assert_eq!(snapshot(&data), before, "{signal}: the earlier dataset changed");
        assert!(staging_dirs(&data).is_empty(), "{signal}: {:?}", staging_dirs(&data));
    }
}

const ROW_HEADER: &str = "case_index,strategy,m_car_kg,direction,mismatch,a95_mg,max_peak_to_peak_mg,car_12x_mps2,\
car_36x_mps2,car_72x_mps2,car_12x_change_db,a95_change_pct,peak_current_a,learning_time_s,travels,backed_off_orders";

fn shard(dir: &Path, name: &str, cases: &[usize]) -> std::path::PathBuf {
    let mut text = format!("{ROW_HEADER}\n");
    for case in cases {
        text.push_str(&format!("{case},adaptive,70.5,up,nominal,2.0,3.0,0.01,0.002,0.001,-30.0,-40.0,12.0,1.5,1,\n"));
    }
    let path = dir.join(name);
    fs::write(&path, text).unwrap();
    path
}

#[test]
fn compare_merge_takes_each_case_once_and_refuses_a_file_that_is_not_a_shard() {
    let tmp = tempfile::tempdir().unwrap();
    let a = shard(tmp.path(), "a.csv", &[0, 1]);
    let b = shard(tmp.path(), "b.csv", &[2]);
    let out = tmp.path().join("merged");
    run_ok(&["compare", "--merge", s(&a), "--merge", s(&b), "--out", s(&out)]);
    let merged = fs::read_to_string(out.join("compare.csv")).unwrap();
    assert_eq!(merged.lines().count(), 4, "{merged}");
    // The same shard twice.
    let err = run_err(&["compare", "--merge", s(&a), "--merge", s(&a), "--out", s(&tmp.path().join("twice"))]);
    assert!(err.contains("case 0") && err.contains("a.csv") && err.contains("again"), "{err}");
    assert!(!tmp.path().join("twice").exists());
    // A header and no row: not a shard.
    let empty = shard(tmp.path(), "empty.csv", &[]);
    let err = run_err(&["compare", "--merge", s(&empty), "--out", s(&tmp.path().join("empty"))]);
    assert!(err.contains("empty.csv") && err.contains("no data row"), "{err}");
}
