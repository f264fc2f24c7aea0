//! Files that exist under their name only when whole: [`Staged`] writes `<name>.partial` and renames
//! it when the writer finishes without error; [`remove_previous_run`] clears a run folder.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use std::fs::File;
use std::io::BufWriter;

use super::{CsvSink, McapSink, OutputError, OutputSink, SampleLayout};
use crate::solve::{Sample, SampleSink};

/// Suffix of a file being written (or whose writing failed or was killed).
pub const PARTIAL_SUFFIX: &str = ".partial";

/// The files a `progmo solve` run writes into its folder, and the temporary names they pass through.
pub const RUN_FILES: [&str; 7] = [
    "summary.json",
    "summary.json.tmp",
    "summary.json.partial",
    "trajectory.csv",
    "trajectory.csv.partial",
    "recording.mcap",
    "recording.mcap.partial",
];

/// `path` with `suffix` appended to its file name (bytes kept: non-UTF-8 names stay as they are).
pub fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut s: OsString = path.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

/// Refuse to write a result file at `path` when something that is not a regular file is there (a
/// device, a FIFO, a directory, a socket, or a link to one): a result is written beside it and
/// renamed over it, which would replace `/dev/null` itself. Nothing there, or a regular file: Ok.
pub fn writable_destination(path: &Path) -> Result<(), OutputError> {
    let kind = match std::fs::metadata(path) {
        Ok(m) => crate::input::not_regular(&m.file_type()),
        Err(_) => match std::fs::symlink_metadata(path) {
            Ok(_) => Some("a dangling symbolic link"),
            Err(_) => None, // nothing there (or no folder: creating the file will say so)
        },
    };
    match kind {
        None => Ok(()),
        Some(k) => Err(OutputError::invalid(
            &path.display().to_string(),
            format!("it is {k}, not a regular file: refusing to replace it with a result file"),
        )),
    }
}

/// Remove the outputs of an earlier run from `dir` (those of [`RUN_FILES`] that exist), so that
/// nothing of it (a summary saying success, an MCAP of another scene) can pass for the next run's.
pub fn remove_previous_run(dir: &Path) -> Result<(), OutputError> {
    for f in RUN_FILES {
        let p = dir.join(f);
        match std::fs::remove_file(&p) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                return Err(OutputError::io(
                    &p.display().to_string(),
                    "remove the earlier run's file",
                    e,
                ))
            }
        }
    }
    Ok(())
}

/// A file sink written under `<path>.partial` and renamed to `path` by a successful `finish`: a
/// reader never finds a truncated file under the real name. On an error (a full device) the
/// partial file stays, named as such, and the error names it.
pub struct Staged<S> {
    inner: S,
    partial: PathBuf,
    path: PathBuf,
    renamed: bool,
}

impl<S: OutputSink> Staged<S> {
    /// Open the sink on `<path>.partial` with `open`.
    pub fn create(
        path: impl AsRef<Path>,
        open: impl FnOnce(&Path) -> Result<S, OutputError>,
    ) -> Result<Self, OutputError> {
        let path = path.as_ref().to_path_buf();
        writable_destination(&path)?;
        let partial = with_suffix(&path, PARTIAL_SUFFIX);
        writable_destination(&partial)?;
        let inner = open(&partial)?;
        Ok(Staged {
            inner,
            partial,
            path,
            renamed: false,
        })
    }

    /// The wrapped sink.
    pub fn inner(&self) -> &S {
        &self.inner
    }

    /// The wrapped sink, e.g. for channels of its own.
    pub fn inner_mut(&mut self) -> &mut S {
        &mut self.inner
    }
}

impl<S: SampleSink> SampleSink for Staged<S> {
    fn sample(&mut self, s: &Sample<'_>) {
        self.inner.sample(s);
    }
    fn warning(&mut self, w: &crate::solve::Warning) {
        self.inner.warning(w);
    }
    fn interrupted(&self) -> bool {
        self.inner.interrupted()
    }
}

impl<S: OutputSink> OutputSink for Staged<S> {
    /// Finish the file, then give it its real name.
    fn finish(&mut self) -> Result<(), OutputError> {
        self.inner.finish()?;
        if !self.renamed {
            writable_destination(&self.path)?;
            std::fs::rename(&self.partial, &self.path).map_err(|e| {
                OutputError::io(
                    &self.partial.display().to_string(),
                    format!("rename to {}", self.path.display()),
                    e,
                )
            })?;
            self.renamed = true;
        }
        Ok(())
    }
}

/// The data files of a `progmo solve` run in a folder: `trajectory.csv` and (optionally)
/// `recording.mcap`, each [`Staged`].
pub struct RunFiles {
    csv: Staged<CsvSink<File>>,
    mcap: Option<Staged<McapSink<BufWriter<File>>>>,
}

impl RunFiles {
    /// Start both files in `dir` (the MCAP only if `mcap`; with the mechanism's frames and
    /// geometry when `bodies` is given).
    pub fn create(
        dir: &Path,
        layout: &SampleLayout,
        mcap: bool,
        bodies: Option<super::Bodies>,
    ) -> Result<Self, OutputError> {
        let csv = Staged::create(dir.join("trajectory.csv"), |p| CsvSink::create(p, layout))?;
        let mcap = if mcap {
            Some(Staged::create(dir.join("recording.mcap"), |p| {
                let m = McapSink::create(p, layout)?;
                Ok(match bodies {
                    Some(b) => m.with_bodies(b),
                    None => m,
                })
            })?)
        } else {
            None
        };
        Ok(RunFiles { csv, mcap })
    }

    /// Finish both files (again: finishing is idempotent) and return every error, one per file.
    pub fn errors(&mut self) -> Vec<OutputError> {
        let rm = self.mcap.as_mut().map(|m| m.finish());
        std::iter::once(self.csv.finish())
            .chain(rm)
            .filter_map(Result::err)
            .collect()
    }
}

impl SampleSink for RunFiles {
    fn sample(&mut self, s: &Sample<'_>) {
        self.csv.sample(s);
        if let Some(m) = &mut self.mcap {
            m.sample(s);
        }
    }
    fn warning(&mut self, w: &crate::solve::Warning) {
        self.csv.warning(w);
        if let Some(m) = &mut self.mcap {
            m.warning(w);
        }
    }
}

impl OutputSink for RunFiles {
    /// Finish both; the CSV's error first if both fail.
    fn finish(&mut self) -> Result<(), OutputError> {
        let rc = self.csv.finish();
        let rm = self.mcap.as_mut().map_or(Ok(()), |m| m.finish());
        rc.and(rm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::testutil::{feed, layout};
    use crate::output::{read_csv, CsvSink};

    #[test]
    fn the_real_name_appears_only_when_whole() {
        let dir = std::env::temp_dir().join(format!("progmo-staged-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.csv");
        let l = layout();
        let mut s = Staged::create(&path, |p| CsvSink::create(p, &l)).unwrap();
        feed(&mut s, &l, 3, 0.5);
        assert!(!path.exists() && dir.join("t.csv.partial").is_file());
        s.finish().unwrap();
        s.finish().unwrap();
        assert!(path.is_file() && !dir.join("t.csv.partial").exists());
        assert_eq!(read_csv(&path).unwrap().len(), 3);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_failed_write_keeps_the_partial_name() {
        // /dev/full accepts the open but fails the flush: the error names the file, no rename.
        let l = layout();
        let mut s = Staged {
            inner: CsvSink::create("/dev/full", &l).unwrap(),
            partial: PathBuf::from("/dev/full"),
            path: PathBuf::from("/nonexistent-dir/never.csv"),
            renamed: false,
        };
        feed(&mut s, &l, 2000, 0.5);
        let e = s.finish().unwrap_err().to_string();
        assert!(e.starts_with("/dev/full: "), "{e}");
        assert!(!s.renamed);
    }

    #[cfg(unix)]
    #[test]
    fn a_device_is_never_a_destination() {
        let l = layout();
        for dev in ["/dev/null", "/dev/full"] {
            let e = Staged::create(dev, |p| CsvSink::create(p, &l))
                .err()
                .expect("refused")
                .to_string();
            assert!(
                e.starts_with(&format!("{dev}: it is a character device")),
                "{e}"
            );
        }
        assert!(!Path::new("/dev/null.partial").exists());
        let dir = std::env::temp_dir();
        assert!(writable_destination(&dir)
            .unwrap_err()
            .to_string()
            .contains("it is a directory"));
    }

    #[cfg(unix)]
    #[test]
    fn suffixes_keep_non_utf8_bytes() {
        use std::os::unix::ffi::OsStrExt;
        let p = Path::new(std::ffi::OsStr::from_bytes(b"/tmp/a\xff.csv"));
        assert_eq!(
            with_suffix(p, PARTIAL_SUFFIX).as_os_str().as_bytes(),
            b"/tmp/a\xff.csv.partial"
        );
    }
}
