//! What the commands write: files in an output directory, and lines on
//! standard output.
//!
//! Files: an [`OutputDir`] stages every file of a run in a hidden directory
//! inside the output directory (same file system, so a rename is atomic) and
//! moves them into place only when the run has succeeded
//! ([`OutputDir::commit`]). A run that fails (or is interrupted) leaves no
//! partial file behind: the staging directory is removed when the
//! `OutputDir` is dropped uncommitted. An existing file is never replaced
//! unless the command was given `--force`: [`OutputDir::refuse_existing`]
//! says so before the work starts, where the names are known, and
//! [`OutputDir::commit`] checks every file again before it moves any.
//!
//! Interruption: SIGINT and SIGTERM (Ctrl-C, `kill`, a CI timeout) remove
//! the run's staging directories and exit with status 130; a signal that
//! arrives while a commit moves files waits until the commit has moved
//! them all, so an output directory holds one run's files or the other's,
//! never half of each. A staging directory left by a run that could not
//! clean up (SIGKILL, a power cut) is removed by the next run that writes
//! to the same directory, once its process has gone. An output directory
//! never lies inside the inputs of the run ([`refuse_inside_inputs`]).
//!
//! Standard output: [`print_line`] (the CLI's `outln!`) writes a line and
//! handles a closed pipe (`host-sim ... | head -1`): the rest of the run's
//! lines are dropped quietly and the command finishes its work; any other
//! write error is kept for [`stdout_error`], which `main` reports.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Mutex, Once};

/// Prefix of the staging directory's name (followed by the process id and a
/// counter); a directory of that name is left behind only by a killed run.
pub const STAGING_PREFIX: &str = ".host-sim-partial-";

/// Error of an [`OutputDir`].
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// Creating, writing or renaming a file or directory failed.
    #[error("cannot write `{}`: {source}", .path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// Cause.
        source: io::Error,
    },
    /// The output directory named is an existing file.
    #[error("the output directory `{}` is a file; expected a directory (new or existing)", .0.display())]
    NotADirectory(PathBuf),
    /// The output directory is, or lies inside, an input of the run.
    #[error(
        "the output directory `{}` is inside the input `{}`: a run never writes into its own inputs, \
         --force or not; give another --out",
        .out.display(),
        .input.display()
    )]
    InsideInput {
        /// The output directory as given.
        out: PathBuf,
        /// The input it lies in, as given.
        input: PathBuf,
    },
    /// Outputs of this run exist already and `--force` was not given.
    #[error(
        "`{}` exists{}; expected a new file: give --force to replace the outputs of an earlier run, or another --out",
        .existing[0].display(),
        more(.existing.len())
    )]
    Exists {
        /// The existing files (at least one).
        existing: Vec<PathBuf>,
    },
}

fn more(count: usize) -> String {
    match count {
        0 | 1 => String::new(),
        n => format!(" (and {} more outputs of this run)", n - 1),
    }
}

/// An output directory whose files are written under a temporary name and
/// published together when the run succeeds (see the module documentation).
#[derive(Debug)]
pub struct OutputDir {
    dir: PathBuf,
    staging: PathBuf,
    force: bool,
    committed: bool,
    /// The directories [`OutputDir::create`] made, deepest first: removed
    /// again (when empty) by a run that fails.
    created: Vec<PathBuf>,
}

impl OutputDir {
    /// Creates `dir` (with parents) and a fresh staging directory in it.
    /// With `force`, existing files of the same names are replaced at
    /// [`OutputDir::commit`]; without, they stop the run.
    pub fn create(dir: &Path, force: bool) -> Result<Self, OutputError> {
        static COUNTER: AtomicU32 = AtomicU32::new(0);
        if fs::metadata(dir).is_ok_and(|m| !m.is_dir()) {
            return Err(OutputError::NotADirectory(dir.to_path_buf()));
        }
        let created: Vec<PathBuf> =
            dir.ancestors().take_while(|d| !d.as_os_str().is_empty() && !d.exists()).map(Path::to_path_buf).collect();
        fs::create_dir_all(dir).map_err(|source| OutputError::Io { path: dir.to_path_buf(), source })?;
        remove_stale_staging(dir);
        install_interrupt_handler();
        loop {
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            let staging = dir.join(format!("{STAGING_PREFIX}{}-{n}", std::process::id()));
            match fs::create_dir(&staging) {
                Ok(()) => {
                    lock(&STAGED_AS).push((staging.clone(), dir.to_path_buf()));
                    return Ok(Self { dir: dir.to_path_buf(), staging, force, committed: false, created });
                }
                // A killed run of a process with the same id left it: take the next.
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(source) => return Err(OutputError::Io { path: staging, source }),
            }
        }
    }

    /// The staging directory: write every output here (or under
    /// [`OutputDir::path`]).
    pub fn staging(&self) -> &Path {
        &self.staging
    }

    /// Where to write the output `name` (a path relative to the output
    /// directory) during the run.
    pub fn path(&self, name: impl AsRef<Path>) -> PathBuf {
        self.staging.join(name)
    }

    /// A buffered writer of the output `name` (see [`OutputDir::path`]);
    /// the error names the file.
    pub fn writer(&self, name: impl AsRef<Path>) -> io::Result<io::BufWriter<std::fs::File>> {
        let path = self.path(name);
        std::fs::File::create(&path)
            .map(io::BufWriter::new)
            .map_err(|e| io::Error::new(e.kind(), format!("cannot write {}: {e}", path.display())))
    }

    /// Where the output `name` will be once published.
    pub fn final_path(&self, name: impl AsRef<Path>) -> PathBuf {
        self.dir.join(name)
    }

    /// The published path of `staged`, a path under the staging directory
    /// (returned unchanged if it is not).
    pub fn published(&self, staged: &Path) -> PathBuf {
        staged.strip_prefix(&self.staging).map_or_else(|_| staged.to_path_buf(), |rel| self.dir.join(rel))
    }

    /// Refuses, unless `--force` was given, when any of the outputs `names`
    /// (relative paths) exists already: call it before the work starts.
    pub fn refuse_existing<I, P>(&self, names: I) -> Result<(), OutputError>
    where
        I: IntoIterator<Item = P>,
        P: AsRef<Path>,
    {
        if self.force {
            return Ok(());
        }
        let existing: Vec<PathBuf> =
            names.into_iter().map(|n| self.dir.join(n)).filter(|p| fs::symlink_metadata(p).is_ok()).collect();
        if existing.is_empty() {
            Ok(())
        } else {
            Err(OutputError::Exists { existing })
        }
    }

    /// Publishes every file of the staging directory into the output
    /// directory (subdirectories created as needed) and removes the staging
    /// directory. Without `--force`, nothing is moved when any of them
    /// exists already. Returns the published files, sorted.
    pub fn commit(mut self) -> Result<Vec<PathBuf>, OutputError> {
        // An interrupt waits for the whole commit (see the module documentation).
        let _moving = lock(&COMMITTING);
        let mut staged = Vec::new();
        staged_files(&self.staging, Path::new(""), &mut staged)?;
        staged.sort();
        if !self.force {
            self.refuse_existing(&staged)?;
        }
        let mut published = Vec::with_capacity(staged.len());
        for relative in &staged {
            let to = self.dir.join(relative);
            if let Some(parent) = to.parent() {
                fs::create_dir_all(parent).map_err(|source| OutputError::Io { path: parent.to_path_buf(), source })?;
            }
            fs::rename(self.staging.join(relative), &to)
                .map_err(|source| OutputError::Io { path: to.clone(), source })?;
            published.push(to);
        }
        fs::remove_dir_all(&self.staging).map_err(|source| OutputError::Io { path: self.staging.clone(), source })?;
        self.committed = true;
        Ok(published)
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.committed {
            // Best effort: a failed run's files must not linger; the run's
            // own error is what gets reported.
            let _ = fs::remove_dir_all(&self.staging);
            for dir in &self.created {
                // Only an empty directory goes: another process may have
                // written there since.
                let _ = fs::remove_dir(dir);
            }
        }
    }
}

/// Refuses an output directory `out` that is one of the folders `inputs`
/// (datasets the run reads) or lies inside one: compared as real paths, so
/// a symbolic link or `..` does not get round it. `out` need not exist yet.
/// A file among `inputs` is no folder to write into (an output directory
/// that is a file is refused by [`OutputDir::create`]).
pub fn refuse_inside_inputs(out: &Path, inputs: &[&Path]) -> Result<(), OutputError> {
    let out_real = real_path(out);
    for input in inputs {
        // A single file given as input (a recording's metadata, an export)
        // is refused as an output directory by `create`; a folder, also
        // what lies inside it.
        let input_real = real_path(input);
        if input_real.is_dir() && out_real.starts_with(&input_real) {
            return Err(OutputError::InsideInput { out: out.to_path_buf(), input: input.to_path_buf() });
        }
    }
    Ok(())
}

/// `path` with its longest existing ancestor resolved
/// (`fs::canonicalize`) and the rest appended: the real path of a
/// directory that is about to be created.
fn real_path(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut rest = Vec::new();
    let mut base = absolute.as_path();
    loop {
        if let Ok(real) = fs::canonicalize(base) {
            return rest.iter().rev().fold(real, |p, c| p.join(c));
        }
        match (base.parent(), base.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                base = parent;
            }
            _ => return absolute,
        }
    }
}

/// Every staging directory of this process with the output directory it
/// stands for: [`public_paths`] puts the latter in messages, an interrupt
/// removes those still there (a committed or dropped run's are gone, and
/// the names, process id and counter, are this process's alone).
static STAGED_AS: Mutex<Vec<(PathBuf, PathBuf)>> = Mutex::new(Vec::new());

/// `message` with every staging directory of this process replaced by the
/// output directory it stands for: an error names the file the user asked
/// for (`out/gap.json`), never the hidden folder it was written in first.
pub fn public_paths(message: &str) -> String {
    let mut text = message.to_string();
    for (staging, dir) in lock(&STAGED_AS).iter() {
        text = text.replace(&staging.display().to_string(), &dir.display().to_string());
    }
    text
}

/// Held while a commit moves files; an interrupt waits for it.
static COMMITTING: Mutex<()> = Mutex::new(());

/// Locks `m`, also after a panic elsewhere poisoned it (the data are paths).
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Installs, once per process, the SIGINT/SIGTERM handler that waits for a
/// commit in progress, removes this process's staging directories and exits with
/// status 130. A process that cannot install it (another handler is set)
/// keeps the default behaviour; the next run then removes what it left.
fn install_interrupt_handler() {
    static INSTALL: Once = Once::new();
    INSTALL.call_once(|| {
        let _ = ctrlc::set_handler(|| {
            let _moving = lock(&COMMITTING);
            for (staging, _) in lock(&STAGED_AS).iter() {
                let _ = fs::remove_dir_all(staging);
            }
            eprintln!("error: interrupted; the outputs this run had not yet published were removed");
            std::process::exit(130);
        });
    });
}

/// Removes the staging directories in `dir` whose process has ended (the
/// process id is part of the name). Where the system gives no way to tell
/// (no `/proc`), nothing is removed.
fn remove_stale_staging(dir: &Path) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) =
            name.to_str().and_then(|n| n.strip_prefix(STAGING_PREFIX)).and_then(|rest| rest.split('-').next())
        else {
            continue;
        };
        let alive = pid.parse::<u32>().is_ok_and(|pid| Path::new("/proc").join(pid.to_string()).exists());
        if !alive && entry.file_type().is_ok_and(|t| t.is_dir()) {
            let _ = fs::remove_dir_all(entry.path());
        }
    }
}

/// The regular files under `root/relative`, as paths relative to `root`.
fn staged_files(root: &Path, relative: &Path, out: &mut Vec<PathBuf>) -> Result<(), OutputError> {
    let dir = root.join(relative);
    let io_err = |source| OutputError::Io { path: dir.clone(), source };
    for entry in fs::read_dir(&dir).map_err(io_err)? {
        let entry = entry.map_err(io_err)?;
        let name = relative.join(entry.file_name());
        if entry.file_type().map_err(io_err)?.is_dir() {
            staged_files(root, &name, out)?;
        } else {
            out.push(name);
        }
    }
    Ok(())
}

/// Set once standard output has been closed by the reader.
static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);
/// The first write error on standard output other than a closed pipe.
static STDOUT_ERROR: Mutex<Option<io::Error>> = Mutex::new(None);

/// Writes `args` and a line end to standard output. A closed pipe (the
/// reader has gone, e.g. `| head -1`) silences every later line; another
/// error is kept for [`stdout_error`] and silences them too. Never panics.
pub fn print_line(args: std::fmt::Arguments<'_>) {
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut stdout = io::stdout().lock();
    let result = stdout.write_fmt(args).and_then(|()| stdout.write_all(b"\n")).and_then(|()| stdout.flush());
    if let Err(e) = result {
        STDOUT_CLOSED.store(true, Ordering::Relaxed);
        if e.kind() != io::ErrorKind::BrokenPipe {
            if let Ok(mut slot) = STDOUT_ERROR.lock() {
                slot.get_or_insert(e);
            }
        }
    }
}

/// The first error writing standard output other than a closed pipe, if any
/// (taken: a second call returns `None`).
pub fn stdout_error() -> Option<io::Error> {
    STDOUT_ERROR.lock().ok().and_then(|mut slot| slot.take())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    }

    #[test]
    fn files_appear_only_when_committed_and_a_failed_run_leaves_nothing() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("out");
        // A run that fails leaves nothing, not even the directories it made.
        {
            let out = OutputDir::create(&dir.join("new"), false).unwrap();
            fs::write(out.path("a.csv"), "half").unwrap();
            assert!(!dir.join("new/a.csv").exists());
        }
        assert!(!dir.exists());
        // ... and in an existing directory, nothing of its own.
        fs::create_dir(&dir).unwrap();
        {
            let out = OutputDir::create(&dir, false).unwrap();
            fs::write(out.path("a.csv"), "half").unwrap();
        }
        assert!(names(&dir).is_empty(), "{:?}", names(&dir));
        // A run that succeeds: files and a subdirectory are published.
        let out = OutputDir::create(&dir, false).unwrap();
        fs::write(out.path("a.csv"), "first").unwrap();
        fs::create_dir_all(out.path("rec")).unwrap();
        fs::write(out.path("rec/b.png"), "png").unwrap();
        assert_eq!(out.published(&out.path("rec/b.png")), dir.join("rec/b.png"));
        let published = out.commit().unwrap();
        assert_eq!(published, vec![dir.join("a.csv"), dir.join("rec/b.png")]);
        assert_eq!(names(&dir), ["a.csv", "rec"]);
        assert_eq!(fs::read_to_string(dir.join("a.csv")).unwrap(), "first");
    }

    #[test]
    fn an_existing_output_is_kept_unless_forced() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        fs::write(dir.join("a.toml"), "user's edited file").unwrap();
        // The early check names the file and the flag.
        let out = OutputDir::create(dir, false).unwrap();
        let err = out.refuse_existing(["b.toml", "a.toml"]).unwrap_err().to_string();
        assert!(err.contains("a.toml") && err.contains("--force"), "{err}");
        // The commit refuses too, and moves nothing (not even the new file).
        fs::write(out.path("a.toml"), "new").unwrap();
        fs::write(out.path("b.toml"), "new").unwrap();
        let err = out.commit().unwrap_err().to_string();
        assert!(err.contains("a.toml") && err.contains("--force"), "{err}");
        assert_eq!(fs::read_to_string(dir.join("a.toml")).unwrap(), "user's edited file");
        assert_eq!(names(dir), ["a.toml"]);
        // With --force the new file replaces it.
        let out = OutputDir::create(dir, true).unwrap();
        out.refuse_existing(["a.toml"]).unwrap();
        fs::write(out.path("a.toml"), "new").unwrap();
        out.commit().unwrap();
        assert_eq!(fs::read_to_string(dir.join("a.toml")).unwrap(), "new");
        assert_eq!(names(dir), ["a.toml"]);
    }

    #[test]
    fn a_staging_directory_of_an_ended_process_is_removed_by_the_next_run() {
        let tmp = tempfile::tempdir().unwrap();
        // A process id above Linux's maximum (2^22) belongs to no process.
        let stale = tmp.path().join(format!("{STAGING_PREFIX}4294967295-0"));
        fs::create_dir(&stale).unwrap();
        fs::write(stale.join("travel.csv"), "half a recording").unwrap();
        // One of a live process (this one) stays.
        let live = tmp.path().join(format!("{STAGING_PREFIX}{}-999999", std::process::id()));
        fs::create_dir(&live).unwrap();
        let out = OutputDir::create(tmp.path(), false).unwrap();
        if Path::new("/proc/self").exists() {
            assert!(!stale.exists(), "the dead run's staging directory is still there");
        }
        assert!(live.exists(), "a live run's staging directory was removed");
        drop(out);
        fs::remove_dir(&live).unwrap();
        assert!(names(tmp.path()).is_empty() || !Path::new("/proc/self").exists(), "{:?}", names(tmp.path()));
    }

    #[test]
    fn an_output_inside_an_input_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let dataset = tmp.path().join("dataset");
        fs::create_dir(&dataset).unwrap();
        fs::write(dataset.join("free_decays.csv"), "t\n").unwrap();
        // The dataset itself, a folder inside it (not yet made), the same
        // folder by `..`.
        for out in [dataset.clone(), dataset.join("results/new"), dataset.join("../dataset")] {
            let err = refuse_inside_inputs(&out, &[&dataset]).unwrap_err().to_string();
            assert!(err.contains("inside the input") && err.contains("dataset"), "{err}");
        }
        // Beside a single recording given as input is fine: it is not
        // a dataset the run reads.
        refuse_inside_inputs(&dataset, &[&dataset.join("free_decays.csv")]).unwrap();
        // A sibling folder is fine, and so is the dataset's parent.
        refuse_inside_inputs(&tmp.path().join("out"), &[&dataset]).unwrap();
        refuse_inside_inputs(tmp.path(), &[&dataset]).unwrap();
    }

    #[test]
    fn messages_name_the_output_directory_not_the_staging_one() {
        let tmp = tempfile::tempdir().unwrap();
        let out = OutputDir::create(tmp.path(), false).unwrap();
        let message = format!("cannot write {}: disk full", out.path("gap.json").display());
        assert!(message.contains(STAGING_PREFIX));
        let public = public_paths(&message);
        assert_eq!(public, format!("cannot write {}: disk full", tmp.path().join("gap.json").display()));
    }

    #[test]
    fn several_existing_outputs_are_counted() {
        let tmp = tempfile::tempdir().unwrap();
        for n in ["x", "y", "z"] {
            fs::write(tmp.path().join(n), "").unwrap();
        }
        let out = OutputDir::create(tmp.path(), false).unwrap();
        let err = out.refuse_existing(["x", "y", "z"]).unwrap_err().to_string();
        assert!(err.contains("and 2 more"), "{err}");
    }
}
