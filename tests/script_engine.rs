//! Scripts end to end on the stepped runtime with simulated time: a program calling a peer's
//! operations as commands (waiting for completion, TRY on rejection), waits with timeouts,
//! state machines with events, conditions and preconditions, lifecycle, stepping, and
//! errors naming file:line:col.
#![allow(clippy::unwrap_used)]

mod script_support;

use hytask::plc::Value;
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

const MACHINE: &str = r#"VAR_GLOBAL
  runs : INT := 2;
  holding : BOOL;
END_VAR
STATE_MACHINE sorter
VAR
  done_runs : INT;
END_VAR
  INITIAL STATE homed
    ENTRY
      DO arm.move_to(0.0);
    END_ENTRY
    TRANSITION WHEN done_runs >= runs TO finished;
    TRANSITION WHEN done_runs < runs TO taking;
  END_STATE
  STATE taking
    ENTRY
      DO arm.move_to(3.0);
      DO arm.grab();
    END_ENTRY
    TRANSITION ON arm.grabbed WHEN holding TO moving;
  END_STATE
  STATE moving
    PRECONDITION holding;
    ENTRY
      DO arm.move_to(-3.0);
      DO arm.drop();
      done_runs := done_runs + 1;
    END_ENTRY
    TRANSITION TO homed;
  END_STATE
  ERROR STATE failed
    ENTRY
      DO arm.move_to(0.0);
    END_ENTRY
  END_STATE
  FINAL STATE finished
  END_STATE
END_STATE_MACHINE
"#;

/// Mirrors the arm's `holding` output into the script each cycle, as a host task would.
fn run_with_holding(c: &mut script_support::Cell, slot: usize, cycles: u64, hold: Option<bool>) {
    let mut holding = c.rt.reader::<bool>("arm.holding").unwrap();
    for _ in 0..cycles {
        let h = hold.unwrap_or(holding.latest().unwrap_or(false));
        c.control.set(slot, "holding", Value::Bool(h)).unwrap();
        c.rt.run_cycles(1);
    }
}

#[test]
fn state_machine_runs_transitions_on_events_and_conditions() {
    let mut c = cell();
    let slot = c.load(MACHINE);
    c.control.control(slot, "sorter", Ctl::Start).unwrap();
    c.rt.run_cycles(1);
    assert_eq!(c.status("sorter").state.as_deref(), Some("homed"));
    run_with_holding(&mut c, slot, 200, None);
    let st = c.status("sorter");
    assert_eq!(st.status, "finished", "{st:?}");
    assert_eq!(st.state.as_deref(), Some("finished"));
    // homed, taking, moving, homed, taking, moving, homed, finished: 7 transitions.
    assert_eq!(st.transitions, 7);
}

/// Runs until the machine moves with the object, then the gripper "loses" it.
fn drop_while_moving(c: &mut script_support::Cell, slot: usize) {
    for _ in 0..100 {
        if c.status("sorter").state.as_deref() == Some("moving") {
            break;
        }
        run_with_holding(c, slot, 1, None);
    }
    assert_eq!(c.status("sorter").state.as_deref(), Some("moving"));
    run_with_holding(c, slot, 100, Some(false));
}

#[test]
fn violated_precondition_goes_to_the_error_state() {
    let mut c = cell();
    let slot = c.load(MACHINE);
    c.control.control(slot, "sorter", Ctl::Start).unwrap();
    drop_while_moving(&mut c, slot);
    let st = c.status("sorter");
    assert_eq!(st.state.as_deref(), Some("failed"), "{st:?}");
    assert_eq!(
        st.status, "running",
        "the error state is a state: it waits there"
    );
    assert_eq!(
        c.rt.reader::<f64>("arm.position").unwrap().latest(),
        Some(0.0)
    );
}

#[test]
fn precondition_without_error_state_stops_the_machine_naming_the_line() {
    let mut c = cell();
    let src = MACHINE.replace("ERROR STATE failed", "STATE failed");
    let slot = c.load(&src);
    c.control.control(slot, "sorter", Ctl::Start).unwrap();
    drop_while_moving(&mut c, slot);
    let st = c.status("sorter");
    assert_eq!(st.status, "error");
    assert_eq!(
        st.error.as_deref(),
        Some("test.st:24:18: precondition violated (no ERROR STATE)")
    );
}

#[test]
fn rejection_outside_try_is_an_error_with_file_line_col() {
    let mut c = cell();
    c.start(
        "PROGRAM p\n  DO arm.move_to(0.5);\n  DO arm.move_to(500.0);\nEND_PROGRAM\n",
        "p",
    );
    assert_eq!(
        c.error_after(10, "p").as_deref(),
        Some("test.st:3:3: command rejected: bad parameters: x_mm outside -100..100")
    );
    assert_eq!(c.status("p").status, "error");
}

#[test]
fn failed_command_and_runtime_fault_name_their_place() {
    let mut c = cell();
    c.start(
        "PROGRAM p\nVAR d : INT; ok : BOOL; END_VAR\n  TRY DO arm.fail(); CATCH ok := TRUE; END_TRY;\n  IF ok THEN d := 10 / d; END_IF;\nEND_PROGRAM\n",
        "p",
    );
    assert_eq!(
        c.error_after(10, "p").as_deref(),
        Some("test.st:4:22: division by zero")
    );
}

#[test]
fn wait_until_times_out_on_simulated_time() {
    let mut c = cell();
    let slot = c.load(
        "VAR_GLOBAL go : BOOL; END_VAR\nPROGRAM p\n  WAIT UNTIL go TIMEOUT T#20ms;\n  WAIT UNTIL go TIMEOUT T#20ms;\nEND_PROGRAM\n",
    );
    c.control.control(slot, "p", Ctl::Start).unwrap();
    c.rt.run_cycles(10);
    assert_eq!(c.status("p").line, 3);
    c.control.set(slot, "go", Value::Bool(true)).unwrap();
    c.rt.run_cycles(1);
    assert_eq!(c.status("p").status, "finished");
    c.control.set(slot, "go", Value::Bool(false)).unwrap();
    c.control.control(slot, "p", Ctl::Start).unwrap();
    c.rt.run_cycles(19);
    assert_eq!(c.status("p").status, "running");
    c.rt.run_cycles(3);
    assert_eq!(
        c.status("p").error.as_deref(),
        Some("test.st:3:3: WAIT timed out")
    );
}

#[test]
fn step_runs_one_statement_at_a_time() {
    let mut c = cell();
    let slot = c.load(
        "VAR_GLOBAL n : INT; END_VAR\nPROGRAM p\n  n := 1;\n  n := 2;\n  WHILE n < 5 DO\n    n := n + 1;\n    WAIT UNTIL TRUE;\n  END_WHILE;\nEND_PROGRAM\n",
    );
    c.control.control(slot, "p", Ctl::Start).unwrap();
    c.control.control(slot, "p", Ctl::Pause).unwrap();
    c.rt.run_cycles(5);
    assert_eq!(
        (c.status("p").status.as_str(), c.status("p").line),
        ("paused", 3)
    );
    let mut lines = Vec::new();
    for _ in 0..5 {
        c.control.control(slot, "p", Ctl::Step).unwrap();
        c.rt.run_cycles(1);
        lines.push(c.status("p").line);
    }
    assert_eq!(lines, vec![4, 5, 6, 7, 5]);
    c.control.control(slot, "p", Ctl::Resume).unwrap();
    c.rt.run_cycles(10);
    assert_eq!(c.status("p").status, "finished");
}

#[test]
fn scripts_follow_the_task_lifecycle() {
    let c = cell();
    let slot = c.load("PROGRAM p\n  DO arm.grab();\nEND_PROGRAM\n");
    let deployment = c.rt.stop();
    let err = c.control.control(slot, "p", Ctl::Start).unwrap_err();
    assert!(
        err.to_string()
            .contains("task 'cell' is Stopped, not running"),
        "{err}"
    );
    drop(deployment);
}

#[test]
fn compile_and_bind_errors_name_file_line_col() {
    let c = cell();
    let err = c
        .control
        .load(
            "bad.st",
            "PROGRAM p\n  DO arm.move_to(TRUE + 1);\n  x := 1;\nEND_PROGRAM\n",
            &c.bindings,
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("bad.st:2:"), "{err}");
    assert!(err.contains("bad.st:3:3:"), "{err}");
    let err = c
        .control
        .load(
            "bad.st",
            "PROGRAM p\n  DO arm.fly(1.0);\n  WAIT arm.landed;\n  DO robot.go();\nEND_PROGRAM\n",
            &c.bindings,
        )
        .unwrap_err()
        .to_string();
    assert_eq!(
        err,
        "bad.st:2:3: task 'arm' has no operation 'fly'\nbad.st:3:3: unknown event 'arm.landed'\nbad.st:4:3: unknown peer task 'robot'"
    );
    let err = c
        .control
        .load(
            "bad.st",
            "STATE_MACHINE m\n  STATE a TRANSITION TO b; END_STATE\nEND_STATE_MACHINE\n",
            &c.bindings,
        )
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("bad.st:1:15: STATE_MACHINE m needs exactly one INITIAL STATE"),
        "{err}"
    );
    assert!(err.contains("bad.st:2:25: no state b in m"), "{err}");
}

#[test]
fn a_machine_starts_and_stops_programs() {
    let mut c = cell();
    let slot = c.load(
        r#"VAR_GLOBAL n : INT; END_VAR
PROGRAM count
  WHILE TRUE DO n := n + 1; WAIT UNTIL TRUE; END_WHILE;
END_PROGRAM
STATE_MACHINE m
  INITIAL STATE a
    ENTRY START count; END_ENTRY
    TRANSITION WHEN n >= 5 TO b;
  END_STATE
  FINAL STATE b
    ENTRY STOP count; END_ENTRY
  END_STATE
END_STATE_MACHINE
"#,
    );
    c.control.control(slot, "m", Ctl::Start).unwrap();
    c.rt.run_cycles(20);
    assert_eq!(c.status("m").status, "finished");
    assert_eq!(c.status("count").status, "stopped");
}

#[test]
fn unload_frees_the_slot() {
    let mut c = cell();
    let slot = c.load("PROGRAM p\n  WAIT UNTIL FALSE;\nEND_PROGRAM\n");
    c.control.control(slot, "p", Ctl::Start).unwrap();
    c.rt.run_cycles(2);
    c.control.unload(slot).unwrap();
    c.rt.run_cycles(1);
    assert!(c.control.status().is_empty());
    assert_eq!(c.load("PROGRAM q\nEND_PROGRAM\n"), slot);
}

/// Several state machines of one task run in parallel: each takes its step in the same task
/// step, so the shorter one finishes while the longer one is still running.
#[test]
fn state_machines_of_one_task_run_in_parallel() {
    let mut c = cell();
    let slot = c.load(
        r#"VAR_GLOBAL a : INT; b : INT; END_VAR
STATE_MACHINE long
  INITIAL STATE counting
    RUN a := a + 1; END_RUN
    TRANSITION WHEN a >= 30 TO done;
  END_STATE
  FINAL STATE done
  END_STATE
END_STATE_MACHINE
STATE_MACHINE short
  INITIAL STATE counting
    RUN b := b + 1; END_RUN
    TRANSITION WHEN b >= 3 TO done;
  END_STATE
  FINAL STATE done
  END_STATE
END_STATE_MACHINE
"#,
    );
    c.control.control(slot, "long", Ctl::Start).unwrap();
    c.control.control(slot, "short", Ctl::Start).unwrap();
    c.rt.run_cycles(10);
    assert_eq!(c.status("short").status, "finished");
    assert_eq!(c.status("long").status, "running");
    assert_eq!(c.status("long").state.as_deref(), Some("counting"));
    c.rt.run_cycles(60);
    assert_eq!(c.status("long").status, "finished");
    assert_eq!(c.status("long").state.as_deref(), Some("done"));
}

/// Consecutive plain statements run as one merged fragment when the budget covers them; a
/// fault inside still names its own statement, and stepping stays statement by statement
/// (`step_runs_one_statement_at_a_time`).
#[test]
fn a_fault_inside_a_run_of_plain_statements_names_its_statement() {
    let mut c = cell();
    c.start(
        "VAR_GLOBAL n : INT; z : INT; END_VAR\nPROGRAM p\n  n := 1;\n  n := 10 / z;\n  n := 3;\nEND_PROGRAM\n",
        "p",
    );
    assert_eq!(
        c.error_after(3, "p").as_deref(),
        Some("test.st:4:11: division by zero")
    );
}
