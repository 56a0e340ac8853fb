//! M66 and #5399 (LinuxCNC semantics): M66 is a queue buster; the interpreter stops after
//! its line and, before the next one, reads the input's value into #5399, or -1 when a wait
//! (L1..L4) timed out, so that the program can branch on it. A live [`Session`] with
//! `live_waits` ends a piece at every M66 and takes the machine's answer with
//! `wait_result`; the whole-program dry run leaves #5399 as it is (rs274 without a machine
//! returns the default, the current value).
#![allow(clippy::unwrap_used)]

use hytask::gcode::{load_str, CanonCmd, InterpOptions, PieceEnd, Session};

const PROG: &str = "G21 G90\nG0 X0 Y0 Z5\n\
    M66 P0 L3 Q0.5\n\
    O100 if [#5399 LT 0]\n  G0 X1\nO100 else\n  G0 X2\nO100 endif\n\
    M66 P1 L1 Q2\n\
    O101 if [#5399 LT 0]\n  G0 Y1\nO101 else\n  G0 Y[2 + #5399]\nO101 endif\n\
    M66 E0 L0\nG0 Z[#5399]\nM2\n";

fn traverses(c: &[hytask::gcode::Canon]) -> Vec<[f64; 9]> {
    c.iter()
        .filter_map(|c| match c.cmd {
            CanonCmd::StraightTraverse(p) => Some(p),
            _ => None,
        })
        .collect()
}

fn wait_line(end: &PieceEnd) -> u32 {
    match end {
        PieceEnd::Wait { loc } => loc.line,
        e => panic!("piece ended with {e:?}, not an M66"),
    }
}

#[test]
fn a_live_session_branches_on_the_machines_answer() {
    let mut s = Session::open_str("m66.ngc", PROG, &InterpOptions::default()).unwrap();
    s.live_waits(true);
    let (c1, end) = s.next_piece().unwrap();
    assert_eq!(wait_line(&end), 3);
    assert!(c1.iter().any(|c| matches!(c.cmd, CanonCmd::Wait { .. })));
    // Asking for more without the answer is refused, naming the M66's line.
    let err = s.next_piece().unwrap_err();
    assert_eq!(err.line, 3, "{err}");
    assert!(!s.finished());
    // The first wait timed out.
    s.wait_result(-1.0);
    let (c2, end) = s.next_piece().unwrap();
    assert_eq!(wait_line(&end), 9);
    assert_eq!(
        traverses(&c2)[0][0],
        1.0,
        "#5399 = -1 takes the timeout branch"
    );
    // The second one was satisfied: a digital input reads 1.
    s.wait_result(1.0);
    let (c3, end) = s.next_piece().unwrap();
    assert_eq!(wait_line(&end), 15);
    assert_eq!(traverses(&c3)[0][1], 3.0, "#5399 = 1: Y[2 + #5399]");
    // L0 on an analog input: the reading itself.
    s.wait_result(4.25);
    let (c4, end) = s.next_piece().unwrap();
    assert_eq!(end, PieceEnd::End);
    assert_eq!(traverses(&c4)[0][2], 4.25);
    assert!(s.finished());
}

#[test]
fn without_live_waits_a_session_and_the_dry_run_keep_5399() {
    let one_shot = load_str("m66.ngc", PROG, &InterpOptions::default()).unwrap();
    let t = traverses(&one_shot.canon);
    // #5399 starts at 0: the "else" branches, and Z0 after the analog read.
    assert!(t.iter().any(|p| p[0] == 2.0));
    assert!(t.iter().any(|p| p[1] == 2.0));
    assert_eq!(t.last().unwrap()[2], 0.0);
    let mut s = Session::open_str("m66.ngc", PROG, &InterpOptions::default()).unwrap();
    let (c, end) = s.next_piece().unwrap();
    assert_eq!(end, PieceEnd::End, "M66 does not end a piece unless asked");
    assert_eq!(traverses(&c), t);
}
