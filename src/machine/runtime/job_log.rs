//! LinuxCNC's log comments on the machine: `(LOGOPEN,name)`, `(LOGAPPEND,name)`,
//! `(LOG,text)` and `(LOGCLOSE)` write a file, as LinuxCNC's task does (probing macros log
//! the points they measure this way).
//!
//! LinuxCNC writes the file as its interpreter reads the line, ahead of motion. hytask
//! writes it when the tool gets there (the machine task reports the item, and this runs on
//! the event bridge thread, never on the servo thread): a job that is aborted logs only
//! what it ran, and a probing job's lines carry the values it measured.
//!
//! A program names the file, and the daemon may run as root, so names are confined to the
//! machine's `[gcode] log_dir`: a relative path inside it, without `..`. Without a log
//! directory, or for a name outside it, nothing is written and the operator gets a message
//! naming the line; a log is never a reason to stop a cut. As in LinuxCNC, `LOG` without an
//! open file is ignored, `LOGOPEN` truncates, `LOGAPPEND` appends, and opening a file closes
//! the one before. The file is closed at `LOGCLOSE` and when the job ends.

use crate::gcode::canon::LogKind;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Component, Path, PathBuf};

/// The log file of one job.
#[derive(Debug, Default)]
pub(super) struct JobLog {
    /// `[gcode] log_dir`.
    dir: Option<PathBuf>,
    /// The open file.
    file: Option<File>,
}

impl JobLog {
    /// A job's log, writing under `dir` (`[gcode] log_dir`), if any.
    pub(super) fn new(dir: Option<PathBuf>) -> Self {
        JobLog { dir, file: None }
    }

    /// Carries out one log comment: `text` is the file name (open, append) or the line
    /// (write). Returns what the operator should be told when it could not be done.
    pub(super) fn apply(&mut self, kind: LogKind, text: &str) -> Result<(), String> {
        match kind {
            LogKind::Open | LogKind::Append => {
                self.file = None;
                let word = if kind == LogKind::Open {
                    "LOGOPEN"
                } else {
                    "LOGAPPEND"
                };
                let Some(dir) = &self.dir else {
                    return Err(format!(
                        "({word},{text}) not written: the machine file has no [gcode] log_dir"
                    ));
                };
                let path = resolve(dir, text).map_err(|e| format!("({word},{text}) {e}"))?;
                let mut options = OpenOptions::new();
                if kind == LogKind::Open {
                    options.write(true).create(true).truncate(true);
                } else {
                    options.append(true).create(true);
                }
                let file = options
                    .open(&path)
                    .map_err(|e| format!("({word},{text}): {}: {e}", path.display()))?;
                self.file = Some(file);
                Ok(())
            }
            LogKind::Write => match &mut self.file {
                // One write per line, so that a line logged is on disk even if the daemon
                // dies later in the job.
                Some(f) => f
                    .write_all(format!("{text}\n").as_bytes())
                    .map_err(|e| format!("(LOG,…): {e}")),
                None => Ok(()),
            },
            LogKind::Close => {
                self.file = None;
                Ok(())
            }
        }
    }
}

/// The path of log file `name` under `dir`: a relative path that stays inside it.
fn resolve(dir: &Path, name: &str) -> Result<PathBuf, String> {
    let rel = Path::new(name.trim());
    if rel.as_os_str().is_empty() {
        return Err("names no file".into());
    }
    if !rel
        .components()
        .all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
    {
        return Err(format!(
            "refused: a log file is named relative to [gcode] log_dir ({}), without '..'",
            dir.display()
        ));
    }
    Ok(dir.join(rel))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn open_write_append_close_as_linuxcnc() -> Result<(), String> {
        let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
        let mut log = JobLog::new(Some(dir.path().to_path_buf()));
        log.apply(LogKind::Write, "before any open: ignored")?;
        log.apply(LogKind::Open, "probe.txt")?;
        log.apply(LogKind::Write, "x=1.000000")?;
        log.apply(LogKind::Close, "")?;
        log.apply(LogKind::Write, "after close: ignored")?;
        log.apply(LogKind::Append, "probe.txt")?;
        log.apply(LogKind::Write, "x=2.000000")?;
        log.apply(LogKind::Close, "")?;
        let read = |n: &str| std::fs::read_to_string(dir.path().join(n)).unwrap_or_default();
        assert_eq!(read("probe.txt"), "x=1.000000\nx=2.000000\n");
        log.apply(LogKind::Open, "probe.txt")?;
        log.apply(LogKind::Write, "again")?;
        assert_eq!(read("probe.txt"), "again\n", "LOGOPEN truncates");
        Ok(())
    }

    #[test]
    fn names_outside_the_log_dir_and_a_missing_dir_are_refused_with_the_reason() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut log = JobLog::new(Some(dir.path().to_path_buf()));
        for name in ["/etc/passwd", "../escape.txt", "a/../../b", "", "  "] {
            let e = log.apply(LogKind::Open, name).expect_err(name);
            assert!(e.starts_with(&format!("(LOGOPEN,{name})")), "{e}");
        }
        assert!(log.file.is_none());
        assert!(
            log.apply(LogKind::Open, "sub/x.txt").is_err(),
            "no such folder"
        );
        let mut none = JobLog::new(None);
        let e = none.apply(LogKind::Append, "x.txt").expect_err("no dir");
        assert!(e.contains("[gcode] log_dir"), "{e}");
    }
}
