//! Scripts end to end on the stepped runtime with simulated time: a program calling a peer's
//! operations as commands (waiting for completion, TRY on rejection), waits with timeouts,
//! state machines with events, conditions and preconditions, lifecycle, stepping, and
//! errors naming file:line:col.
#![allow(clippy::unwrap_used)]

mod script_support;

use hytask::script::Ctl;
use script_support::cell;
use std::sync::atomic::Ordering;

const PICK: &str = r#"
VAR_GLOBAL
  count : INT;
END_VAR
PROGRAM pick
VAR
  x : LREAL := 5.0;
  ok : BOOL;
END_VAR
  DO arm.move_to(x);
  TRY
    DO arm.move_to(1000.0);
  CATCH
    ok := TRUE;
  END_TRY;
  IF ok THEN
    DO arm.grab();
    WAIT arm.grabbed TIMEOUT T#10ms;
  END_IF;
  count := count + 1;
  EMIT done;
END_PROGRAM
"#;

#[test]
fn program_calls_operations_and_waits_for_completion() {
    let mut c = cell();
    let slot = c.load(PICK);
    c.control.control(slot, "pick", Ctl::Start).unwrap();
    let mut pos = c.rt.reader::<f64>("arm.position").unwrap();
    c.rt.run_cycles(3);
    assert_eq!(c.status("pick").status, "running");
    assert_eq!(c.status("pick").line, 10, "waiting in the first DO");
    assert!(pos.latest().unwrap() < 5.0);
    c.rt.run_cycles(20);
    assert_eq!(pos.latest(), Some(5.0));
    c.rt.run_cycles(5);
    let st = c.status("pick");
    // The rejected move was caught (ok), the grab's event (emitted while its command ran)
    // satisfied the WAIT, the program ended.
    assert_eq!(st.status, "finished", "{st:?}");
    assert_eq!(st.error, None);
    assert_eq!(c.done.load(Ordering::Relaxed), 1);
    assert_eq!(
        c.rt.reader::<bool>("arm.holding").unwrap().latest(),
        Some(true)
    );
}
