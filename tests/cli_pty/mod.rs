//! The real `hytask` binary on a pseudo-terminal, as a person runs it: its stdin, stdout and
//! stderr are the pty's slave side (so it draws progress as on a terminal), and it leads its
//! own process group, to which the test sends SIGINT as the terminal does on Ctrl-C.
//!
//! Every wait is a hang guard ([`GUARD`]): the tests act on what the binary printed, never
//! after a sleep.
#![allow(clippy::unwrap_used, dead_code)]

use nix::sys::signal::{killpg, Signal};
use nix::unistd::Pid;
use std::io::{Read, Write};
use std::os::fd::OwnedFd;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Hang guard of every wait: a loaded 2-CPU host may run the machine much slower.
pub const GUARD: Duration = Duration::from_secs(120);

/// A `hytask` child on a pty.
pub struct PtyChild {
    child: Child,
    master: std::fs::File,
    /// Everything the child printed (stdout and stderr interleaved, as on the terminal).
    out: Arc<Mutex<String>>,
    /// How far [`expect`](Self::expect) has consumed `out`.
    seen: usize,
    /// The thread copying the master side into `out`; it ends when the child has exited.
    reader: Option<std::thread::JoinHandle<()>>,
}

impl PtyChild {
    /// Starts `hytask ARGS` with the pty as its terminal, in a new process group.
    pub fn spawn(args: &[&std::ffi::OsStr]) -> PtyChild {
        let pty = nix::pty::openpty(None, None).unwrap();
        let slave = |fd: &OwnedFd| Stdio::from(fd.try_clone().unwrap());
        let child = Command::new(env!("CARGO_BIN_EXE_hytask"))
            .args(args)
            .env("RUST_LOG", "warn")
            .stdin(slave(&pty.slave))
            .stdout(slave(&pty.slave))
            .stderr(slave(&pty.slave))
            .process_group(0)
            .spawn()
            .unwrap();
        // Only the child holds the slave now: reading the master ends (EIO) when it exits.
        drop(pty.slave);
        let master = std::fs::File::from(pty.master);
        let out = Arc::new(Mutex::new(String::new()));
        let (mut reader, sink) = (master.try_clone().unwrap(), out.clone());
        let reader = std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = reader.read(&mut buf) {
                if n == 0 {
                    break;
                }
                sink.lock()
                    .unwrap()
                    .push_str(&String::from_utf8_lossy(&buf[..n]));
            }
        });
        PtyChild {
            child,
            master,
            out,
            seen: 0,
            reader: Some(reader),
        }
    }

    /// Waits until the output after the previous match contains `text`; returns the output
    /// up to and including it.
    pub fn expect(&mut self, text: &str) -> String {
        let t0 = Instant::now();
        loop {
            {
                let out = self.out.lock().unwrap();
                if let Some(i) = out[self.seen..].find(text) {
                    let end = self.seen + i + text.len();
                    let got = out[self.seen..end].to_string();
                    self.seen = end;
                    return got;
                }
            }
            if let Some(status) = self.child.try_wait().unwrap() {
                self.drain();
                let out = self.out.lock().unwrap();
                if !out[self.seen..].contains(text) {
                    panic!("hytask exited ({status}) without printing {text:?}:\n{out}");
                }
                continue;
            }
            assert!(
                t0.elapsed() < GUARD,
                "timed out waiting for {text:?}; output:\n{}",
                self.out.lock().unwrap()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits until the reader has copied everything the exited child wrote.
    fn drain(&mut self) {
        if let Some(r) = self.reader.take() {
            r.join().unwrap();
        }
    }

    /// Ctrl-C: SIGINT to the child's process group, as the terminal sends it.
    pub fn ctrl_c(&self) {
        killpg(Pid::from_raw(self.child.id() as i32), Signal::SIGINT).unwrap();
    }

    /// Types `text` on the terminal.
    pub fn type_text(&mut self, text: &str) {
        self.master.write_all(text.as_bytes()).unwrap();
    }

    /// Waits for the child to exit; returns its status and its whole output.
    pub fn wait(mut self) -> (ExitStatus, String) {
        let t0 = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                self.drain();
                return (status, self.out.lock().unwrap().clone());
            }
            if t0.elapsed() > GUARD {
                let _ = self.child.kill();
                panic!("hytask did not exit; output:\n{}", self.out.lock().unwrap());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for PtyChild {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}
