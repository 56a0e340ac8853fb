//! Scripts allocate nothing after load: a state machine and programs that send commands,
//! wait for their completion, catch rejections and failures, wait for events and
//! conditions with timeouts, start and stop programs, run for thousands of steps under the
//! counting allocator, which counts every allocation made inside a realtime step (the
//! stepped runtime marks its steps like the real threads do).
#![allow(clippy::unwrap_used)]

mod counting_alloc;
mod script_support;

use hytask::script::Ctl;

const SRC: &str = r#"VAR_GLOBAL
  n : DINT;
  caught : DINT;
END_VAR
PROGRAM shuttle
VAR
  x : LREAL := 4.0;
END_VAR
  WHILE TRUE DO
    DO arm.move_to(x);
    x := -x;
    TRY
      DO arm.move_to(x * 1000.0);
    CATCH
      caught := caught + 1;
    END_TRY;
    TRY
      DO arm.fail();
    CATCH
      caught := caught + 1;
    END_TRY;
    DO arm.grab();
    WAIT arm.grabbed TIMEOUT T#1s;
    TRY
      WAIT UNTIL FALSE TIMEOUT T#2ms;
    CATCH
      n := n + 1;
    END_TRY;
  END_WHILE;
END_PROGRAM
PROGRAM ticker
  WHILE TRUE DO n := n + 1; WAIT UNTIL TRUE; END_WHILE;
END_PROGRAM
STATE_MACHINE m
VAR
  k : DINT;
END_VAR
  INITIAL STATE a
    ENTRY START ticker; END_ENTRY
    RUN k := k + 1; END_RUN
    TRANSITION WHEN k MOD 10 = 9 TO b;
  END_STATE
  STATE b
    PRECONDITION n >= 0;
    ENTRY STOP ticker; END_ENTRY
    TRANSITION ON arm.reached TO a;
  END_STATE
  FINAL STATE z
  END_STATE
END_STATE_MACHINE
"#;

#[test]
fn script_steps_do_not_allocate() {
    let mut c = script_support::cell();
    let slot = c.load(SRC);
    for item in ["shuttle", "m"] {
        c.control.control(slot, item, Ctl::Start).unwrap();
    }
    c.rt.run_cycles(100);
    let before = counting_alloc::in_rt_steps();
    c.rt.run_cycles(5_000);
    let st = c.control.status();
    for s in &st {
        assert!(s.status == "running" || s.name == "ticker", "{s:?}");
        assert_eq!(s.error, None);
    }
    let m = st.iter().find(|s| s.name == "m").unwrap();
    assert!(m.transitions > 100, "{m:?}");
    let allocs = counting_alloc::in_rt_steps() - before;
    assert_eq!(
        allocs,
        0,
        "first allocation in a step:\n{}",
        counting_alloc::first_rt_backtrace().unwrap_or_default()
    );
}
