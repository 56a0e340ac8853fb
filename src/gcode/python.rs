//! LinuxCNC's embedded Python in the interpreter: O-word procedures written in Python (the
//! `oword` module that the ini's `[PYTHON] TOPLEVEL` imports) and `;py,` comments.
//!
//! hytask links no Python. The interpreter runs in the job-preparation thread, never in the
//! realtime path, so Python runs there too, in a `python3` child process started when it is
//! first needed (an `o<…> call` with the ini's `[PYTHON]` section, or a `;py,` comment) and
//! ended with the interpreter. Only where the interpreter's options enable it
//! ([`crate::gcode::InterpOptions::python`]): a G-code file alone never runs code on the host. [`BRIDGE`] (`python_bridge.py`) is the child's program: it
//! gives Python LinuxCNC's `interpreter` and `emccanon` modules and `self.params`, and
//! forwards every parameter access and canonical call to the interpreter over the child's
//! pipes, one JSON object per line. The interpreter's side of the conversation is in
//! `interp/pycall.rs`.

use serde::Deserialize;
use std::io::{BufRead as _, BufReader, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

/// The bridge program run by the child process.
pub const BRIDGE: &str = include_str!("python_bridge.py");

/// Compiles the bridge (its first argument) under a file name of its own, so that its frames
/// can be told from the user's in tracebacks.
const LOADER: &str =
    "import sys\nexec(compile(sys.argv[1], '<hytask bridge>', 'exec'), {'__name__': '__main__'})";

/// What an ini file's `[PYTHON]` section configures.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PythonConfig {
    /// `TOPLEVEL`: the file run at start-up; it imports `oword`, whose functions are O-word
    /// procedures. Relative to the ini file's directory.
    pub toplevel: Option<PathBuf>,
    /// `PATH_PREPEND`: directories put in front of Python's module path.
    pub path_prepend: Vec<PathBuf>,
    /// `PATH_APPEND`: directories put after it.
    pub path_append: Vec<PathBuf>,
    /// The Python interpreter to run (default `python3` from `PATH`).
    pub python: PathBuf,
}

impl PythonConfig {
    /// Python enabled without an ini's `[PYTHON]` section: `;py,` comments run, no O-word
    /// procedures (`hytask gcode canon --python`).
    pub fn bare() -> PythonConfig {
        PythonConfig {
            python: PathBuf::from("python3"),
            ..PythonConfig::default()
        }
    }

    /// The `[PYTHON]` section of an ini file's `text`, if it has one; relative paths are
    /// taken from `dir` (the ini file's directory). `PATH_PREPEND`/`PATH_APPEND` may repeat
    /// and hold colon-separated lists.
    pub fn from_ini(text: &str, dir: &Path) -> Option<PythonConfig> {
        let mut cfg = None::<PythonConfig>;
        let mut inside = false;
        for line in text.lines().map(str::trim) {
            if line.starts_with(['#', ';']) {
                continue;
            }
            if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
                inside = name.trim().eq_ignore_ascii_case("PYTHON");
                if inside && cfg.is_none() {
                    cfg = Some(PythonConfig::bare());
                }
                continue;
            }
            let (Some(c), true) = (cfg.as_mut(), inside) else {
                continue;
            };
            let Some((name, value)) = line.split_once('=') else {
                continue;
            };
            let value = value.trim();
            let paths = || {
                value
                    .split(':')
                    .filter(|p| !p.is_empty())
                    .map(|p| dir.join(p))
                    .collect::<Vec<_>>()
            };
            match name.trim().to_ascii_uppercase().as_str() {
                "TOPLEVEL" if !value.is_empty() => c.toplevel = Some(dir.join(value)),
                "PATH_PREPEND" => c.path_prepend.extend(paths()),
                "PATH_APPEND" => c.path_append.extend(paths()),
                _ => {}
            }
        }
        cfg
    }
}

/// Why the Python child could not do what was asked.
#[derive(Debug, thiserror::Error)]
pub enum PyError {
    /// The interpreter could not be started.
    #[error("cannot start the Python interpreter {python:?} (needed for embedded Python: an ini [PYTHON] section or a ';py,' comment): {source}")]
    Spawn {
        /// The program.
        python: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The pipes to the child failed, or it ended.
    #[error("the Python child process stopped: {0}")]
    Io(#[from] std::io::Error),
    /// The interpretation was cancelled while Python ran (the child is killed).
    #[error("Interpretation cancelled while Python was running")]
    Cancelled,
    /// The child said something that is not the protocol.
    #[error("the Python child process sent {line:?}: {why}")]
    Protocol {
        /// What it sent.
        line: String,
        /// What is wrong with it.
        why: String,
    },
}

/// A parameter key: `self.params[5220]` or `self.params["_x"]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub(crate) enum Key {
    /// Numbered parameter.
    Num(f64),
    /// Named parameter.
    Name(String),
}

/// What the child sends while it runs a request.
#[derive(Debug, Deserialize)]
#[serde(tag = "ev", rename_all = "lowercase")]
pub(crate) enum Event {
    /// Start-up done.
    Ready,
    /// Text Python wrote to its stdout.
    Print {
        /// The text (partial lines possible).
        text: String,
    },
    /// Read a parameter (answered with its value).
    Get {
        /// Which.
        key: Key,
    },
    /// Set a parameter (answered).
    Set {
        /// Which.
        key: Key,
        /// The new value.
        value: f64,
    },
    /// The call level (answered).
    Level,
    /// An `emccanon` call (answered).
    Canon {
        /// Its name, as LinuxCNC spells it.
        name: String,
        /// Its numeric arguments (the line number of the motion calls dropped).
        args: Vec<f64>,
        /// Its text (MESSAGE, COMMENT).
        text: Option<String>,
    },
    /// The request finished.
    Done {
        /// `none`, `float`, `bool` (has), `str`, or another Python type name.
        kind: String,
        /// The value, if any.
        value: Option<serde_json::Value>,
    },
    /// The request raised an exception.
    Error {
        /// The exception (`AssertionError`, `ValueError: boom`).
        msg: String,
        /// Where in Python it was raised (`file:line`), if known.
        at: String,
    },
}

/// The running child.
pub(crate) struct Bridge {
    child: Child,
    tx: ChildStdin,
    rx: BufReader<ChildStdout>,
    line: String,
}

impl std::fmt::Debug for Bridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bridge")
            .field("pid", &self.child.id())
            .finish()
    }
}

impl Bridge {
    /// Starts the child with `cfg` (none: `;py,` comments without a `[PYTHON]` section).
    /// Its start-up (running TOPLEVEL) is then run by the caller, up to [`Event::Ready`].
    pub(crate) fn spawn(cfg: Option<&PythonConfig>) -> Result<Bridge, PyError> {
        let python = cfg.map_or_else(|| PathBuf::from("python3"), |c| c.python.clone());
        let strs = |v: &[PathBuf]| {
            v.iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
        };
        let conf = serde_json::json!({
            "toplevel": cfg.and_then(|c| c.toplevel.as_ref()).map(|p| p.display().to_string()),
            "prepend": cfg.map(|c| strs(&c.path_prepend)).unwrap_or_default(),
            "append": cfg.map(|c| strs(&c.path_append)).unwrap_or_default(),
        });
        let mut child = Command::new(&python)
            .args(["-B", "-c", LOADER, BRIDGE, &conf.to_string()])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|source| PyError::Spawn {
                python: python.clone(),
                source,
            })?;
        let (Some(tx), Some(rx)) = (child.stdin.take(), child.stdout.take()) else {
            let _ = child.kill();
            let _ = child.wait();
            return Err(PyError::Io(std::io::Error::other("no pipes to the child")));
        };
        Ok(Bridge {
            child,
            tx,
            rx: BufReader::new(rx),
            line: String::new(),
        })
    }

    /// Sends one JSON object.
    pub(crate) fn send(&mut self, v: &serde_json::Value) -> Result<(), PyError> {
        let mut s = v.to_string();
        s.push('\n');
        self.tx.write_all(s.as_bytes())?;
        self.tx.flush()?;
        Ok(())
    }

    /// Receives the next event. While it waits, `cancel` (the interpretation's cancel flag)
    /// is polled every 100 ms: a Python procedure that never returns must not keep a
    /// cancelled job's preparation busy forever.
    pub(crate) fn recv(
        &mut self,
        cancel: Option<&std::sync::atomic::AtomicBool>,
    ) -> Result<Event, PyError> {
        if let Some(c) = cancel {
            use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
            use std::os::fd::AsFd as _;
            while self.rx.buffer().is_empty() {
                let mut fds = [PollFd::new(self.rx.get_ref().as_fd(), PollFlags::POLLIN)];
                match poll(&mut fds, PollTimeout::from(100u16)) {
                    Ok(0) | Err(nix::errno::Errno::EINTR) => {}
                    Ok(_) => break,
                    Err(e) => return Err(PyError::Io(e.into())),
                }
                if c.load(std::sync::atomic::Ordering::Relaxed) {
                    let _ = self.child.kill();
                    return Err(PyError::Cancelled);
                }
            }
        }
        self.line.clear();
        if self.rx.read_line(&mut self.line)? == 0 {
            let status = self.child.wait()?;
            return Err(PyError::Io(std::io::Error::other(format!(
                "it exited ({status})"
            ))));
        }
        serde_json::from_str(self.line.trim_end()).map_err(|e| PyError::Protocol {
            line: self.line.trim_end().chars().take(200).collect(),
            why: e.to_string(),
        })
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn python_section_paths_are_relative_to_the_ini() {
        let text = "[EMC]\nTOPLEVEL = no\n[PYTHON]\nPATH_PREPEND = .:lib\nPATH_APPEND=/abs\n\
                    TOPLEVEL = subs.py\n; TOPLEVEL = other.py\n[CONFIG]\nX = 1\n";
        let c = PythonConfig::from_ini(text, Path::new("/cfg")).unwrap();
        assert_eq!(c.toplevel, Some(PathBuf::from("/cfg/subs.py")));
        assert_eq!(
            c.path_prepend,
            vec![PathBuf::from("/cfg/."), PathBuf::from("/cfg/lib")]
        );
        assert_eq!(c.path_append, vec![PathBuf::from("/abs")]);
        assert_eq!(c.python, PathBuf::from("python3"));
        assert!(PythonConfig::from_ini("[EMC]\nX=1\n", Path::new(".")).is_none());
    }
}
