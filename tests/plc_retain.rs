//! RETAIN variables survive a restart: the state file is written off the scan (atomically)
//! and restored before the first scan of the next start; other variables start fresh.
#![allow(clippy::unwrap_used)]

use hytask::plc::{compile, retain, Options, Value};
use std::time::{Duration, Instant};

const SRC: &str = "PROGRAM P\nVAR RETAIN n : DINT; t : TIME; END_VAR\nVAR k : DINT; END_VAR\n\
                   n := n + 1; k := k + 1; t := t + T#10ms;\nEND_PROGRAM\n";

#[test]
fn retain_values_survive_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plc.retain");
    let mut p = compile("r.st", SRC, Options::default()).unwrap();
    let r = retain::start(&mut p, &path).unwrap();
    for s in 0..5 {
        p.scan(&[], &mut [], s).unwrap();
        r.shared.publish(&p, &r.ids);
    }
    drop(r); // the task is gone: the writer writes once more and stops
    let t0 = Instant::now();
    let text = loop {
        let text = std::fs::read_to_string(&path).unwrap_or_default();
        if text.contains("P.n=5") {
            break text;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "not written: {text:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(text.contains("P.t=T#50ms"), "{text}");
    assert!(!text.contains("P.k"), "only RETAIN variables: {text}");
    assert!(
        !dir.path().join("plc.tmp").exists(),
        "the temporary file was renamed"
    );

    let mut q = compile("r.st", SRC, Options::default()).unwrap();
    let _r = retain::start(&mut q, &path).unwrap();
    assert_eq!(q.get(q.var("P.n").unwrap()), Value::Int(5));
    assert_eq!(q.get(q.var("P.k").unwrap()), Value::Int(0));
}

#[test]
fn a_bad_state_file_is_refused_naming_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plc.retain");
    std::fs::write(&path, "P.t=T#1s\nP.n=TRUE\n").unwrap();
    let mut p = compile("r.st", SRC, Options::default()).unwrap();
    let e = retain::start(&mut p, &path).err().unwrap().to_string();
    assert!(e.contains("plc.retain:2") && e.contains("P.n"), "{e}");
}
