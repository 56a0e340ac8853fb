//! Taking the control socket's path: a lock file, a private directory, and the socket.
//!
//! A daemon takes the path *before* it deploys anything (locks memory, starts the servo
//! thread, opens buses): a second daemon must find the path taken while the first one still
//! owns the machine, not after it has opened the bus the first one drives. Ownership is an
//! `flock` on `<socket>.lock` next to the socket, held for the life of the daemon; the
//! kernel drops it when the process dies, so a crashed daemon leaves no false owner.
//!
//! The socket's directory must not be writable by other users (as /tmp is): someone else
//! could take or replace the path first. And only a stale *socket* is ever removed from the
//! path: a regular file there is an error, not something to delete.

use std::os::fd::AsRawFd;
use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

/// Where and how to create the socket.
#[derive(Debug, Clone)]
pub struct SocketOptions {
    /// Socket path (default [`default_socket_path`]).
    pub path: PathBuf,
    /// File mode, e.g. 0o660.
    pub mode: u32,
    /// Group that owns the socket, if any.
    pub group: Option<String>,
}

impl SocketOptions {
    /// Options from the config's `[control]` section; `path` overrides its `socket_path`.
    pub fn from_config(config: &crate::config::ControlConfig, path: Option<PathBuf>) -> Self {
        SocketOptions {
            path: path.unwrap_or_else(|| config.socket_path.clone()),
            mode: config.mode.0,
            group: config.group.clone(),
        }
    }
}

/// Why the socket could not be created.
#[derive(Debug, thiserror::Error)]
pub enum BindError {
    /// Another daemon holds the path.
    #[error("{0}: another daemon is already listening there")]
    InUse(PathBuf),
    /// Something that is not a socket occupies the path.
    #[error("{0}: exists and is not a socket; refusing to replace it (remove it or choose another control.socket_path / --socket)")]
    NotASocket(PathBuf),
    /// The directory would let another user take the path.
    #[error("{dir}: {why}; the control socket needs a directory only its owner can write, such as $XDG_RUNTIME_DIR/hytask or /run/hytask (control.socket_path / --socket)")]
    UnsafeDir {
        /// The directory.
        dir: PathBuf,
        /// What is wrong with it.
        why: String,
    },
    /// A filesystem or socket error.
    #[error("{path}: {source}")]
    Io {
        /// Path involved.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The configured group does not exist.
    #[error("control.group: no group named '{0}'")]
    NoSuchGroup(String),
}

/// The default socket path: see [`crate::config::default_socket_path`].
pub fn default_socket_path() -> PathBuf {
    crate::config::default_socket_path()
}

/// The path taken: its lock, then (after [`Claim::bind`]) its socket. Dropping it removes
/// the socket file if it is still ours and releases the lock.
#[derive(Debug)]
pub struct Claim {
    opts: SocketOptions,
    lock: std::fs::File,
    socket_ino: Option<u64>,
}

/// A bound, listening socket with the claim on its path.
#[derive(Debug)]
pub struct Listener {
    /// The listening socket (non-blocking).
    pub socket: std::os::unix::net::UnixListener,
    claim: Claim,
}

impl Listener {
    /// The socket path.
    pub fn path(&self) -> &Path {
        &self.claim.opts.path
    }

    /// The socket, and the claim to hold as long as the daemon owns the machine.
    pub fn into_parts(self) -> (std::os::unix::net::UnixListener, Claim) {
        (self.socket, self.claim)
    }
}

/// Claims the path: creates the directory if needed, checks that no other user can write
/// it, and takes the lock. Nothing is created at the socket path itself yet.
pub fn claim(opts: &SocketOptions) -> Result<Claim, BindError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| BindError::Io { path, source }
    };
    let dir = match opts.path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !dir.exists() {
        use std::os::unix::fs::DirBuilderExt;
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o755)
            .create(&dir)
            .map_err(io(&dir))?;
    }
    check_private_dir(&dir)?;
    let lock_path = lock_path(&opts.path);
    let lock = {
        use std::os::unix::fs::OpenOptionsExt;
        std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
            .open(&lock_path)
            .map_err(io(&lock_path))?
    };
    // SAFETY: flock on a descriptor we own; no memory is involved.
    if unsafe { libc::flock(lock.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
        let e = std::io::Error::last_os_error();
        return Err(if e.kind() == std::io::ErrorKind::WouldBlock {
            BindError::InUse(opts.path.clone())
        } else {
            BindError::Io {
                path: lock_path,
                source: e,
            }
        });
    }
    Ok(Claim {
        opts: opts.clone(),
        lock,
        socket_ino: None,
    })
}

impl Claim {
    /// Creates the listening socket on the claimed path: replaces a stale socket (one
    /// nobody answers on), refuses anything else there, applies mode and group.
    pub fn bind(mut self) -> Result<Listener, BindError> {
        let path = self.opts.path.clone();
        let io = |source| BindError::Io {
            path: path.clone(),
            source,
        };
        match std::fs::symlink_metadata(&path) {
            Ok(m) if m.file_type().is_socket() => {
                if std::os::unix::net::UnixStream::connect(&path).is_ok() {
                    // A daemon of a build without the lock file answers there.
                    return Err(BindError::InUse(path));
                }
                std::fs::remove_file(&path).map_err(io)?;
            }
            Ok(_) => return Err(BindError::NotASocket(path)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(io(e)),
        }
        let socket = std::os::unix::net::UnixListener::bind(&path).map_err(io)?;
        self.socket_ino = std::fs::symlink_metadata(&path).ok().map(|m| m.ino());
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(self.opts.mode))
            .map_err(io)?;
        if let Some(group) = &self.opts.group {
            let gid = nix::unistd::Group::from_name(group)
                .ok()
                .flatten()
                .ok_or_else(|| BindError::NoSuchGroup(group.clone()))?
                .gid;
            nix::unistd::chown(&path, None, Some(gid))
                .map_err(|e| io(std::io::Error::from_raw_os_error(e as i32)))?;
        }
        socket.set_nonblocking(true).map_err(io)?;
        Ok(Listener {
            socket,
            claim: self,
        })
    }
}

impl Drop for Claim {
    fn drop(&mut self) {
        // Remove the socket only if the path still holds the one we bound.
        if let Some(ino) = self.socket_ino {
            if std::fs::symlink_metadata(&self.opts.path).is_ok_and(|m| m.ino() == ino) {
                let _ = std::fs::remove_file(&self.opts.path);
            }
        }
        let _ = &self.lock;
    }
}

/// Claims the path and binds the socket in one step.
pub fn bind(opts: &SocketOptions) -> Result<Listener, BindError> {
    claim(opts)?.bind()
}

fn lock_path(socket: &Path) -> PathBuf {
    let mut s = socket.as_os_str().to_owned();
    s.push(".lock");
    PathBuf::from(s)
}

/// Refuses a directory that another user could write (or own): there they could take the
/// socket path first, or replace the socket under the daemon.
fn check_private_dir(dir: &Path) -> Result<(), BindError> {
    let m = std::fs::metadata(dir).map_err(|source| BindError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let unsafe_dir = |why: String| BindError::UnsafeDir {
        dir: dir.to_path_buf(),
        why,
    };
    let me = nix::unistd::geteuid().as_raw();
    if m.uid() != me && m.uid() != 0 {
        return Err(unsafe_dir(format!(
            "owned by uid {}, not by this daemon (uid {me}) or root",
            m.uid()
        )));
    }
    let mode = m.mode() & 0o7777;
    if mode & 0o022 != 0 {
        return Err(unsafe_dir(format!(
            "writable by {} (mode {mode:04o})",
            if mode & 0o002 != 0 {
                "all users"
            } else {
                "its group"
            }
        )));
    }
    Ok(())
}
