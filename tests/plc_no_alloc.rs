//! A PLC scan allocates nothing: the whole program (timers, counters, user blocks and
//! functions, loops, dynamic array indexing, the bound process image) runs many scans under
//! the counting allocator after one warm-up scan, and so does the faulting path.
#![allow(clippy::unwrap_used)]

use hytask::plc::{compile, Options, Value};

mod counting_alloc;
mod machine_rig;

use counting_alloc::during as allocations;

const SRC: &str = r#"
TYPE Axis : STRUCT pos : LREAL; homed : BOOL; END_STRUCT END_TYPE
FUNCTION Clamp : DINT
VAR_INPUT x, lo, hi : DINT; END_VAR
Clamp := LIMIT(lo, x, hi);
END_FUNCTION
FUNCTION_BLOCK Debounce
VAR_INPUT raw : BOOL; t : TIME := T#30ms; END_VAR
VAR_OUTPUT q : BOOL; END_VAR
VAR on : TON; off : TOF; END_VAR
on(IN := raw, PT := t);
off(IN := on.Q, PT := t);
q := off.Q;
END_FUNCTION_BLOCK
PROGRAM Main
VAR_INPUT button : BOOL; divisor : INT := 1; END_VAR
VAR_OUTPUT lamp : BOOL; count : INT; END_VAR
VAR
  db : Debounce;
  ctr : CTU;
  hist : ARRAY[0..15] OF DINT;
  i, k : DINT;
  axes : ARRAY[1..3] OF Axis;
  trig : ARRAY[0..3] OF R_TRIG;
  w : WORD;
  q : INT;
END_VAR
db(raw := button);
ctr(CU := db.q, R := count > 100, PV := 10);
count := ctr.CV;
lamp := ctr.Q OR db.q;
k := (k + 1) MOD 16;
hist[k] := Clamp(x := count * 3, lo := 0, hi := 200);
FOR i := 0 TO 15 DO
  IF hist[i] > 100 THEN EXIT; END_IF;
  axes[i MOD 3 + 1].pos := axes[i MOD 3 + 1].pos + 0.5;
END_FOR;
trig[k MOD 4](CLK := button);
w.3 := trig[k MOD 4].Q;
q := 100 / divisor;
END_PROGRAM
"#;

#[test]
fn scans_do_not_allocate() {
    let mut p = compile("alloc.st", SRC, Options::default()).unwrap();
    let button = p.var("button").unwrap();
    let lamp = p.var("Main.lamp").unwrap();
    let count = p.var("count").unwrap();
    p.bind(
        &[button],
        &[(lamp, Value::Bool(false)), (count, Value::Int(0))],
    );
    let mut outs = [Value::Bool(false), Value::Int(0)];
    p.scan(&[Value::Bool(false)], &mut outs, 0).unwrap();
    let mut presses = 0;
    let n = allocations(|| {
        for s in 1..20_000i64 {
            let pressed = s % 20 < 10;
            presses += (s % 20 == 0) as u32;
            p.scan(&[Value::Bool(pressed)], &mut outs, s * 10_000_000)
                .unwrap();
        }
    });
    assert_eq!(n, 0, "allocations during 20,000 scans");
    assert!(
        presses > 0 && outs[1] != Value::Int(0),
        "the program did work: {outs:?}"
    );
}

#[test]
fn a_faulting_scan_does_not_allocate() {
    let mut p = compile("alloc.st", SRC, Options::default()).unwrap();
    let divisor = p.var("divisor").unwrap();
    let lamp = p.var("lamp").unwrap();
    p.bind(&[divisor], &[(lamp, Value::Bool(false))]);
    let mut outs = [Value::Bool(true)];
    p.scan(&[Value::Int(1)], &mut outs, 0).unwrap();
    let mut faults = 0;
    let n = allocations(|| {
        for s in 1..1000i64 {
            if p.scan(&[Value::Int(0)], &mut outs, s).is_err() {
                faults += 1;
            }
            p.reset_fault();
        }
    });
    assert_eq!(n, 0);
    assert_eq!(faults, 999);
    assert_eq!(outs[0], Value::Bool(false), "outputs at their safe values");
}

/// The machine's servo cycle with the mill's PLC task beside it (config/sim.toml with its
/// `[plc]`, on the stepped runtime): a job with coolant, an M6 handshake with the carousel
/// and a feed move, a guard door opened mid-move (feed hold) and closed, an e-stop. Nothing
/// allocates on either thread once running.
#[test]
fn the_servo_and_plc_cycle_allocates_nothing() {
    use hytask::gcode::CanonCmd;
    use hytask::machine::servo::machine_task::MachineCmd;
    use hytask::machine::servo::{ports, MachineSnapshot};
    use hytask::rt::prelude::*;

    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut text = std::fs::read_to_string(root.join("config/sim.toml")).unwrap();
    for (from, to) in [
        ("initial_position = 150.0", "initial_position = 298.0"),
        ("initial_position = -50.0", "initial_position = -2.0"),
    ] {
        text = text.replace(from, to);
    }
    let mut cfg = hytask::config::parse(&text, "sim.toml").unwrap();
    cfg.plc.as_mut().unwrap().base_dir = Some(root.join("config"));
    let h = machine_rig::homed(&cfg);
    let mut snap: DataReader<MachineSnapshot> = h.rt.reader(ports::SNAPSHOT).unwrap();
    let start = h.start;
    let mut end = start;
    end[0] = 100.0;
    let run = h.queue_job(
        1,
        start,
        &[
            CanonCmd::FloodOn,
            CanonCmd::StartChange,
            CanonCmd::ChangeTool(4),
            CanonCmd::SetFeedRate(1200.0),
            CanonCmd::StraightFeed(end),
        ],
    );
    let machine_rig::Homed {
        mut rt,
        machine,
        sim_io,
        fb,
        ..
    } = h;
    let mut fb = fb.into_iter().next().unwrap();
    let _run = machine.send(run).unwrap();
    rt.run_cycles(50);
    let io = sim_io[0].clone().unwrap();
    let door = 3; // config/sim.toml: estop, probe, spindle_at_speed, door_open, estop_reset

    let before = counting_alloc::so_far();
    rt.run_cycles(1500); // the carousel turns 4 pockets (400 ms), then the move starts
    let tool = snap.latest().unwrap().tool;
    let moved = fb.latest().unwrap().actual;
    io.set_digital_input(door, true).unwrap();
    rt.run_cycles(1000);
    let held = snap.latest().unwrap().mode;
    io.set_digital_input(door, false).unwrap();
    rt.run_cycles(100);
    let resume = machine.send(MachineCmd::Resume).unwrap();
    rt.run_cycles(500);
    io.set_digital_input(0, true).unwrap();
    rt.run_cycles(500);
    let during = counting_alloc::so_far() - before;

    assert_eq!(tool, 4, "the PLC finished the M6");
    assert!(moved < start[0] - 1.0, "the machine moved after the M6");
    assert_eq!(
        held,
        hytask::machine::api::Mode::Holding,
        "the door held feed"
    );
    assert_eq!(resume.status(), CommandStatus::Done);
    assert_eq!(
        during, 0,
        "{during} allocations in 3600 servo cycles with the PLC"
    );
}
