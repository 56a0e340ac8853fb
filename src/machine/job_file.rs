//! Reading a job file for `job.load`, safely: a request names a path on the daemon's host,
//! and the daemon may be root, so the path is untrusted input.
//!
//! - Outside the jobs directory (`[control] jobs_dir`, symbolic links resolved) a path is
//!   refused without being opened.
//! - Only a regular file is read. The file is opened non-blocking and checked with `fstat`
//!   on the opened descriptor, so a FIFO never blocks the reader and `/dev/urandom` never
//!   fills memory; what is checked is what is read.
//! - The read is capped (`[control] max_job_bytes`), whatever the file claims its size is.
//!
//! The policy comes from the control socket's configuration, not from the machine's, so the
//! server installs it around each request with [`with_policy`]; without one the defaults
//! of [`JobFilePolicy::default`] apply (no directory restriction, 256 MiB).

use crate::machine::api::ApiError;
use std::cell::RefCell;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Default cap of a job file, bytes (`[control] max_job_bytes`).
pub const DEFAULT_MAX_JOB_BYTES: u64 = 256 * 1024 * 1024;

/// What `job.load` may read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JobFilePolicy {
    /// Jobs must lie under this directory (canonical form is taken when checking).
    pub jobs_dir: Option<PathBuf>,
    /// Largest file read, bytes.
    pub max_bytes: u64,
}

impl Default for JobFilePolicy {
    fn default() -> Self {
        JobFilePolicy {
            jobs_dir: None,
            max_bytes: DEFAULT_MAX_JOB_BYTES,
        }
    }
}

thread_local! {
    static POLICY: RefCell<Option<JobFilePolicy>> = const { RefCell::new(None) };
}

/// Runs `f` with `policy` governing every [`read`] on this thread.
pub fn with_policy<R>(policy: &JobFilePolicy, f: impl FnOnce() -> R) -> R {
    let previous = POLICY.with(|p| p.replace(Some(policy.clone())));
    let r = f();
    POLICY.with(|p| *p.borrow_mut() = previous);
    r
}

fn current_policy() -> JobFilePolicy {
    POLICY.with(|p| p.borrow().clone()).unwrap_or_default()
}

/// Reads the job file at `path` under the current policy. Errors are content-free: they
/// name the path, the rule and the limit, never bytes of the file.
pub fn read(path: &str) -> Result<String, ApiError> {
    read_with(path, &current_policy())
}

/// [`read`] with an explicit policy.
pub fn read_with(path: &str, policy: &JobFilePolicy) -> Result<String, ApiError> {
    let refuse = |why: String| ApiError::InvalidParams(format!("job {path}: {why}"));
    let canonical = std::fs::canonicalize(path).map_err(|e| refuse(format!("cannot open: {e}")))?;
    let dir = match &policy.jobs_dir {
        Some(d) => {
            let dir = std::fs::canonicalize(d).map_err(|e| {
                refuse(format!(
                    "the jobs directory {} (control.jobs_dir) is not usable: {e}",
                    d.display()
                ))
            })?;
            if !canonical.starts_with(&dir) {
                return Err(refuse(format!(
                    "outside the jobs directory {} (control.jobs_dir)",
                    dir.display()
                )));
            }
            Some(dir)
        }
        None => None,
    };
    let file = open_nonblocking(&canonical).map_err(|e| refuse(format!("cannot open: {e}")))?;
    if let Some(dir) = &dir {
        // A directory renamed or a link swapped between the check and the open: check what
        // was opened.
        if let Ok(opened) = std::fs::read_link(fd_path(&file)) {
            if !opened.starts_with(dir) {
                return Err(refuse(format!(
                    "outside the jobs directory {} (control.jobs_dir)",
                    dir.display()
                )));
            }
        }
    }
    let meta = file
        .metadata()
        .map_err(|e| refuse(format!("cannot stat: {e}")))?;
    if !meta.file_type().is_file() {
        return Err(refuse(format!(
            "not a regular file ({}); only regular files are loaded",
            kind(&meta.file_type())
        )));
    }
    let too_big = |n: u64| {
        refuse(format!(
            "{n} bytes or more, larger than the limit of {} bytes (control.max_job_bytes)",
            policy.max_bytes
        ))
    };
    if meta.len() > policy.max_bytes {
        return Err(too_big(meta.len()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(policy.max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| refuse(format!("cannot read: {e}")))?;
    if bytes.len() as u64 > policy.max_bytes {
        return Err(too_big(bytes.len() as u64));
    }
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let line = 1 + e.as_bytes()[..at].iter().filter(|&&b| b == b'\n').count();
        refuse(format!(
            "not UTF-8 text (invalid byte on line {line}, byte offset {at})"
        ))
    })
}

fn open_nonblocking(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY)
        .open(path)
}

fn fd_path(file: &std::fs::File) -> PathBuf {
    use std::os::fd::AsRawFd;
    PathBuf::from(format!("/proc/self/fd/{}", file.as_raw_fd()))
}

fn kind(t: &std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if t.is_dir() {
        "a directory"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy(dir: Option<&Path>, max: u64) -> JobFilePolicy {
        JobFilePolicy {
            jobs_dir: dir.map(Path::to_path_buf),
            max_bytes: max,
        }
    }

    #[test]
    fn a_regular_file_within_the_limit_is_read() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.ngc");
        std::fs::write(&p, "G0 X1\nM2\n").unwrap();
        let text = read_with(p.to_str().unwrap(), &policy(Some(d.path()), 100)).unwrap();
        assert_eq!(text, "G0 X1\nM2\n");
    }

    #[test]
    fn devices_fifos_and_directories_are_refused_without_blocking() {
        let e = read_with("/dev/urandom", &JobFilePolicy::default()).unwrap_err();
        assert!(e.to_string().contains("character device"), "{e}");
        let d = tempfile::tempdir().unwrap();
        let fifo = d.path().join("fifo.ngc");
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::from_bits_truncate(0o600)).unwrap();
        // Nobody writes the FIFO: a blocking open or read would hang this test.
        let e = read_with(fifo.to_str().unwrap(), &JobFilePolicy::default()).unwrap_err();
        assert!(e.to_string().contains("FIFO"), "{e}");
        let e = read_with(d.path().to_str().unwrap(), &JobFilePolicy::default()).unwrap_err();
        assert!(e.to_string().contains("directory"), "{e}");
    }

    #[test]
    fn a_file_over_the_cap_is_refused_naming_the_limit_and_key() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("big.ngc");
        std::fs::write(&p, vec![b'G'; 1001]).unwrap();
        let e = read_with(p.to_str().unwrap(), &policy(None, 1000)).unwrap_err();
        let m = e.to_string();
        assert!(
            m.contains("1000 bytes") && m.contains("control.max_job_bytes"),
            "{m}"
        );
    }

    #[test]
    fn paths_outside_the_jobs_dir_are_refused_symlinks_resolved() {
        let jobs = tempfile::tempdir().unwrap();
        let other = tempfile::tempdir().unwrap();
        let secret = other.path().join("secret.ngc");
        std::fs::write(&secret, "root:x:0:0\n").unwrap();
        let link = jobs.path().join("link.ngc");
        std::os::unix::fs::symlink(&secret, &link).unwrap();
        let p = policy(Some(jobs.path()), 1000);
        for path in [
            secret.clone(),
            link,
            jobs.path().join("../").join(other.path()),
        ] {
            let e = read_with(path.to_str().unwrap(), &p)
                .unwrap_err()
                .to_string();
            assert!(e.contains("control.jobs_dir"), "{e}");
            assert!(!e.contains("root:x"), "{e}");
        }
    }

    #[test]
    fn invalid_utf8_is_refused_without_quoting_bytes() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("bin.ngc");
        std::fs::write(&p, b"G0 X1\n\xff\xfe secret").unwrap();
        let e = read_with(p.to_str().unwrap(), &JobFilePolicy::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 2, byte offset 6") && !e.contains("secret"),
            "{e}"
        );
    }

    #[test]
    fn the_installed_policy_applies_on_this_thread_only_while_installed() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.ngc");
        std::fs::write(&p, "G0 X1\n").unwrap();
        let path = p.to_str().unwrap();
        let e = with_policy(&policy(None, 3), || read(path)).unwrap_err();
        assert!(e.to_string().contains("limit of 3 bytes"), "{e}");
        assert!(read(path).is_ok());
    }
}
