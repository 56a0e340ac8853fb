//! Where `hytask gcode canon` writes a long trace while it is still being produced.
//!
//! The trace of a program with an error must not be printed at all (the error alone is the
//! answer, as for a job). Holding the whole trace in memory meets that, but a 150,000-line
//! CAM file gives ~9 MB of text, and faulting in those fresh pages was about a fifth of the
//! run. When standard output is a regular file or `/dev/null`, a partial trace can be taken
//! back (the file is cut back to where it started), so the trace is written out in chunks
//! from a buffer that stays small. A pipe or a terminal cannot take text back: there the
//! whole trace is still held until the program is known to be valid.

use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::os::unix::fs::FileTypeExt;

/// Bytes of trace gathered before they are written out.
pub const CHUNK: usize = 256 * 1024;

/// A destination that can discard what it was given (see the module doc).
#[derive(Debug)]
pub struct Spill {
    file: File,
    /// Offset to cut a regular file back to; `None` for `/dev/null`.
    start: Option<u64>,
    /// The first write error; later chunks are dropped.
    error: Option<std::io::Error>,
}

impl Spill {
    /// A spill onto `file` when it can discard (a regular file opened for writing, or the null
    /// device); `None` for pipes, terminals and anything else.
    pub fn onto(mut file: File) -> Option<Self> {
        let meta = file.metadata().ok()?;
        let kind = meta.file_type();
        let start = if kind.is_file() {
            // Appended text goes to the end whatever the position (`>>` in a shell).
            let fd = std::os::fd::AsRawFd::as_raw_fd(&file);
            let flags = nix::fcntl::fcntl(fd, nix::fcntl::FcntlArg::F_GETFL).ok()?;
            let append =
                nix::fcntl::OFlag::from_bits_truncate(flags).contains(nix::fcntl::OFlag::O_APPEND);
            Some(if append {
                meta.len()
            } else {
                file.stream_position().ok()?
            })
        } else if kind.is_char_device() && is_null_device(&meta) {
            None
        } else {
            return None;
        };
        Some(Spill {
            file,
            start,
            error: None,
        })
    }

    /// Writes `buf` out and empties it once it holds a chunk.
    pub fn take_chunk(&mut self, buf: &mut Vec<u8>) {
        if buf.len() >= CHUNK {
            self.write(buf);
            buf.clear();
        }
    }

    /// Writes the rest and reports the first write error.
    pub fn finish(mut self, rest: &[u8]) -> std::io::Result<()> {
        self.write(rest);
        if self.error.is_none() {
            if let Err(e) = self.file.flush() {
                self.error = Some(e);
            }
        }
        self.error.map_or(Ok(()), Err)
    }

    /// Takes back everything written so far (the program had an error).
    pub fn discard(&mut self) {
        if let Some(start) = self.start {
            // Best effort: a file that cannot be cut back keeps the partial trace, and the
            // error that caused the discard is reported either way.
            let _ = self.file.set_len(start);
            let _ = self.file.seek(SeekFrom::Start(start));
        }
    }

    fn write(&mut self, bytes: &[u8]) {
        if self.error.is_none() {
            if let Err(e) = self.file.write_all(bytes) {
                self.error = Some(e);
            }
        }
    }
}

/// Whether `meta` is the null device (major 1, minor 3 on Linux).
fn is_null_device(meta: &std::fs::Metadata) -> bool {
    use std::os::unix::fs::MetadataExt;
    let rdev = meta.rdev();
    nix::sys::stat::major(rdev) == 1 && nix::sys::stat::minor(rdev) == 3
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("hytask-spill-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir.join(name)
    }

    /// A regular file keeps what was there before and gets the trace; a discard takes the
    /// trace back to the old end.
    #[test]
    fn regular_file_writes_and_takes_back() {
        let path = temp("trace.txt");
        std::fs::write(&path, b"header\n").expect("write");
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .expect("open");
        f.seek(SeekFrom::End(0)).expect("seek");
        let mut s = Spill::onto(f.try_clone().expect("clone")).expect("a file spills");
        let mut buf = vec![b'x'; CHUNK];
        s.take_chunk(&mut buf);
        assert!(buf.is_empty(), "a full chunk is written out");
        assert_eq!(std::fs::read(&path).expect("read").len(), 7 + CHUNK);
        s.discard();
        assert_eq!(std::fs::read(&path).expect("read"), b"header\n");

        let mut s = Spill::onto(f).expect("a file spills");
        let mut buf = b"small".to_vec();
        s.take_chunk(&mut buf);
        assert_eq!(buf, b"small", "less than a chunk stays");
        s.finish(&buf).expect("finish");
        assert_eq!(std::fs::read(&path).expect("read"), b"header\nsmall");
    }

    /// The null device spills; a pipe does not (it cannot take text back).
    #[test]
    fn null_spills_pipe_does_not() {
        let null = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/null")
            .expect("null");
        assert!(Spill::onto(null).is_some());
        let (_r, w) = nix::unistd::pipe().expect("pipe");
        assert!(Spill::onto(File::from(w)).is_none());
    }
}
