//! The real daemon against abuse from its socket: jobs that are not files or too big, paths
//! outside the jobs directory, files whose content must not leak, a shutdown while a request
//! blocks, a second daemon on the same socket, and logs written to a pipe.
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use support::*;

/// sim-fast with extra `[control]` keys, written into `dir`.
fn config_with_control(dir: &Path, extra: &str) -> PathBuf {
    let base = std::fs::read_to_string(fast_sim()).unwrap();
    let start = base.find("[control]\n").unwrap();
    let end = start + base[start..].find("\n\n").unwrap_or(base.len() - start);
    let text = format!(
        "{}[control]\nmode = \"0660\"\n{extra}\n{}",
        &base[..start],
        &base[end..]
    );
    let path = dir.join("machine.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn sigterm_while_a_job_load_blocks_ends_the_process_cleanly() {
    let mut d = Daemon::start(&fast_sim());
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("job.ngc");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::from_bits_truncate(0o600)).unwrap();
    let mut c = d.client();
    let path = fifo.display().to_string();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(c.call("job.load", json!({ "path": path })));
    });
    // Either the daemon refuses the FIFO, or it opened it and now waits in a read: then our
    // (non-blocking) open of the write end succeeds, and we keep it open without writing.
    let t0 = Instant::now();
    let _writer = loop {
        use std::os::unix::fs::OpenOptionsExt;
        if let Ok(reply) = rx.try_recv() {
            let e = reply.unwrap_err().to_string();
            assert!(e.contains("FIFO"), "{e}");
            break None;
        }
        if let Ok(w) = std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(&fifo)
        {
            break Some(w);
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "job.load never came"
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    let (status, err) = d.terminate();
    assert!(status.success(), "{status:?}\n{err}");
}

#[test]
fn job_load_refuses_fifos_devices_and_files_over_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = config_with_control(dir.path(), "max_job_bytes = 2000");
    let d = Daemon::start(&cfg);
    let mut c = d.client();
    ready(&mut c);
    let fifo = dir.path().join("fifo.ngc");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::from_bits_truncate(0o600)).unwrap();
    let (_, m) = err(
        &mut c,
        "job.load",
        json!({"path": fifo.display().to_string()}),
    );
    assert!(m.contains("not a regular file"), "{m}");
    let (_, m) = err(&mut c, "job.load", json!({"path": "/dev/urandom"}));
    assert!(m.contains("not a regular file"), "{m}");
    let big = dir.path().join("big.ngc");
    std::fs::write(&big, "G0 X1\n".repeat(400)).unwrap();
    let (_, m) = err(
        &mut c,
        "job.load",
        json!({"path": big.display().to_string()}),
    );
    assert!(
        m.contains("2000 bytes") && m.contains("control.max_job_bytes"),
        "{m}"
    );
    // A job within the limit loads.
    let small = dir.path().join("small.ngc");
    std::fs::write(&small, "G21 G90\nG0 X10 Y10\nM2\n").unwrap();
    ok(
        &mut c,
        "job.load",
        json!({"path": small.display().to_string()}),
    );
}

#[test]
fn jobs_outside_the_jobs_dir_are_refused_and_non_gcode_files_are_not_quoted() {
    let dir = tempfile::tempdir().unwrap();
    let jobs = dir.path().join("jobs");
    std::fs::create_dir(&jobs).unwrap();
    let cfg = config_with_control(dir.path(), &format!("jobs_dir = {:?}", jobs.display()));
    let d = Daemon::start(&cfg);
    let mut c = d.client();
    ready(&mut c);
    for outside in [
        "/etc/passwd".to_string(),
        format!("{}/../machine.toml", jobs.display()),
    ] {
        let (_, m) = err(&mut c, "job.load", json!({ "path": outside }));
        assert!(m.contains("control.jobs_dir"), "{m}");
        assert!(!m.contains("root:") && !m.contains("[machine]"), "{m}");
    }
    let link = jobs.join("link.ngc");
    std::os::unix::fs::symlink("/etc/passwd", &link).unwrap();
    let (_, m) = err(
        &mut c,
        "job.load",
        json!({"path": link.display().to_string()}),
    );
    assert!(m.contains("control.jobs_dir"), "{m}");
    // Inside the directory, a file that is not a G-code program: the error says where,
    // not what the file holds.
    let secret = jobs.join("shadow");
    std::fs::write(&secret, "root:$6$topsecret:19000:0:99999:7:::\n").unwrap();
    let (code, m) = err(
        &mut c,
        "job.load",
        json!({"path": secret.display().to_string()}),
    );
    assert_eq!(code, 3);
    assert!(m.contains("not a G-code program"), "{m}");
    assert!(!m.contains("topsecret") && !m.contains("root"), "{m}");
    // A G-code program inside it loads, and its errors still quote it.
    let part = jobs.join("part.ngc");
    std::fs::write(&part, "G21\nG1 X10 F600 $\nM2\n").unwrap();
    let (_, m) = err(
        &mut c,
        "job.load",
        json!({"path": part.display().to_string()}),
    );
    assert!(m.contains("part.ngc:2:"), "{m}");
    std::fs::write(&part, "G21 G90\nG0 X10 Y10\nM2\n").unwrap();
    ok(
        &mut c,
        "job.load",
        json!({"path": part.display().to_string()}),
    );
}

#[test]
fn a_second_daemon_stops_before_it_deploys_the_machine() {
    let d = Daemon::start(&fast_sim());
    // The second daemon is the CANopen router: deploying it would open the CAN bus. In this
    // build that deployment fails with "not available", so its error shows which step came
    // first: finding the socket taken, or deploying.
    let canopen = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/example-canopen.toml");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(["serve", "--config"])
        .arg(&canopen)
        .arg("--socket")
        .arg(&d.socket)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("already listening"), "{err}");
    assert!(
        !err.contains("not available"),
        "deployed before refusing: {err}"
    );
    // The first daemon is untouched.
    let mut c = d.client();
    ok(&mut c, "status", serde_json::Value::Null);
}

#[test]
fn serve_refuses_to_replace_a_regular_file_at_the_socket_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("notes.txt");
    std::fs::write(&path, "keep me").unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(["serve", "--config"])
        .arg(fast_sim())
        .arg("--socket")
        .arg(&path)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("not a socket"), "{err}");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "keep me");
}

#[test]
fn logs_to_a_pipe_carry_no_colour_codes() {
    let mut d = Daemon::start(&fast_sim());
    let mut c = d.client();
    ok(&mut c, "status", serde_json::Value::Null);
    drop(c);
    let (status, err) = d.terminate();
    assert!(status.success());
    assert!(err.contains("control socket at"), "{err}");
    assert!(!err.contains('\u{1b}'), "ANSI escape codes in: {err:?}");
}

#[test]
fn serve_refuses_a_socket_in_a_directory_other_users_can_write() {
    // /tmp-like: world-writable with the sticky bit.
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o1777)).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(["serve", "--config"])
        .arg(fast_sim())
        .arg("--socket")
        .arg(dir.path().join("control.sock"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("writable by all users"), "{err}");
    assert!(!dir.path().join("control.sock").exists());
}

#[test]
fn the_client_and_the_daemon_default_to_the_same_private_socket_path() {
    // root: the system path.
    assert_eq!(
        hytask::config::default_socket_path(),
        PathBuf::from("/run/hytask/control.sock")
    );
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .arg("status")
        .env_remove("HYTASK_SOCKET")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/run/hytask/control.sock"), "{err}");
    // Another user: its runtime directory, for the client and for `hytask serve`.
    use std::os::unix::fs::PermissionsExt;
    use std::os::unix::process::CommandExt;
    let runtime = tempfile::tempdir().unwrap();
    std::fs::set_permissions(runtime.path(), std::fs::Permissions::from_mode(0o700)).unwrap();
    nix::unistd::chown(
        runtime.path(),
        Some(nix::unistd::Uid::from_raw(65534)),
        Some(nix::unistd::Gid::from_raw(65534)),
    )
    .unwrap();
    let expected = runtime.path().join("hytask/control.sock");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .arg("status")
        .env_remove("HYTASK_SOCKET")
        .env("XDG_RUNTIME_DIR", runtime.path())
        .uid(65534)
        .gid(65534)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&expected.display().to_string()), "{err}");
    // sim-fast without its socket_path, readable by that user.
    let cfg = config_with_control(runtime.path(), "");
    std::fs::set_permissions(&cfg, std::fs::Permissions::from_mode(0o644)).unwrap();
    let mut daemon = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(["serve", "--config"])
        .arg(&cfg)
        .env("XDG_RUNTIME_DIR", runtime.path())
        .uid(65534)
        .gid(65534)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while hytask::control::client::Client::connect(&expected).is_err() {
        if let Some(status) = daemon.try_wait().unwrap() {
            let mut e = String::new();
            use std::io::Read;
            daemon
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut e)
                .unwrap();
            panic!("daemon exited {status:?}: {e}");
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no socket at {expected:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(["status", "--json"])
        .env_remove("HYTASK_SOCKET")
        .env("XDG_RUNTIME_DIR", runtime.path())
        .uid(65534)
        .gid(65534)
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(daemon.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let status = daemon.wait().unwrap();
    assert!(status.success());
}
