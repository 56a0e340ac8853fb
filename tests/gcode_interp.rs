//! The interpreter through its public interface: what each feature produces, where it
//! says it came from, and how it refuses bad programs (whole-program refusal, file/line/
//! column, one clear error per limit).
#![allow(clippy::unwrap_used)]

use hytask::gcode::canon::{InputKind, Plane, ProbeKind, WaitKind};
use hytask::gcode::{load_file, load_str, CanonCmd, GcodeError, InterpOptions, Limits, Program};

fn run(text: &str) -> Program {
    load_str("t.ngc", text, &InterpOptions::default()).unwrap()
}

fn err(text: &str) -> GcodeError {
    load_str("t.ngc", text, &InterpOptions::default()).unwrap_err()
}

fn err_with(text: &str, opts: &InterpOptions) -> GcodeError {
    load_str("t.ngc", text, opts).unwrap_err()
}

/// The commands produced by the program body (after the start-up calls, line > 0).
fn body(p: &Program) -> Vec<CanonCmd> {
    p.canon
        .iter()
        .filter(|c| c.loc.line > 0)
        .map(|c| c.cmd.clone())
        .collect()
}

fn feeds(p: &Program) -> Vec<[f64; 3]> {
    p.canon
        .iter()
        .filter_map(|c| match &c.cmd {
            CanonCmd::StraightFeed(e) => Some([e[0], e[1], e[2]]),
            _ => None,
        })
        .collect()
}

#[test]
fn every_command_carries_its_source_location() {
    let p = run("G21\n  G0 X1\nG1 X2 F100 M3 S10\nM2\n");
    let trav = p
        .canon
        .iter()
        .find(|c| matches!(c.cmd, CanonCmd::StraightTraverse(_)))
        .unwrap();
    assert_eq!((&*trav.loc.file, trav.loc.line), ("t.ngc", 2));
    let spindle = p
        .canon
        .iter()
        .find(|c| matches!(c.cmd, CanonCmd::StartSpindle(_)))
        .unwrap();
    assert_eq!((spindle.loc.line, spindle.loc.col), (3, 12));
    assert_eq!(p.canon[0].loc.line, 0, "start-up calls carry line 0");
}

#[test]
fn errors_name_file_line_column_and_refuse_the_whole_program() {
    let e = err("G21\nG0 X1\nG1 G0 X2\nM2\n");
    assert_eq!((e.file.as_str(), e.line, e.col), ("t.ngc", 3, 4));
    assert!(e.message.contains("same modal group"), "{e}");
    assert_eq!(
        e.to_string(),
        "t.ngc:3:4: Two g codes used from same modal group"
    );
}

#[test]
fn missing_program_end_is_an_error() {
    let e = err("G0 X1\n");
    assert!(e.message.contains("no percent sign or program end"));
    assert!(run("%\nG0 X1\n%\nG0 X2\n")
        .canon
        .iter()
        .any(|c| c.cmd == CanonCmd::Finish));
}

#[test]
fn straight_moves_absolute_incremental_and_g53() {
    let p = run("G21 G10 L2 P1 X10\nG1 X1 Y2 Z3 F100\nG91 X1\nG90 G53 G1 X0\nM2\n");
    assert_eq!(
        feeds(&p),
        vec![[1.0, 2.0, 3.0], [2.0, 2.0, 3.0], [-10.0, 2.0, 3.0]]
    );
}

#[test]
fn arcs_center_radius_full_circle_helix_turns() {
    let p = run("G21 G17 F100\nG2 X10 Y0 I5 J0\nG3 X10 Y0 I-5 J0 Z-1 P2\nG18 G2 X0 Z0 R6\nM2\n");
    let arcs: Vec<_> = body(&p)
        .into_iter()
        .filter_map(|c| match c {
            CanonCmd::ArcFeed {
                first_center,
                second_center,
                rotation,
                axis_end,
                plane,
                end,
                ..
            } => Some((first_center, second_center, rotation, axis_end, plane, end)),
            _ => None,
        })
        .collect();
    assert_eq!(arcs.len(), 3);
    assert_eq!((arcs[0].0, arcs[0].1, arcs[0].2), (5.0, 0.0, -1));
    assert_eq!((arcs[1].2, arcs[1].3), (2, -1.0));
    assert_eq!(arcs[2].4, Plane::Xz);
    assert_eq!(arcs[2].5[0], 0.0);
    let e = err("G21 F10\nG2 X1 Y0 I0.6 J0\nM2\n");
    assert!(e.message.starts_with("Radius to end of arc differs"), "{e}");
}

#[test]
fn units_and_offsets_arrive_as_their_own_commands() {
    let p = run("G20\nG10 L2 P2 X1\nG55\nG92 X0\nG43.1 Z0.5\nM2\n");
    let b = body(&p);
    assert!(b.contains(&CanonCmd::UseLengthUnits(
        hytask::gcode::LengthUnits::Inches
    )));
    assert!(b.iter().any(|c| matches!(c, CanonCmd::SetG5xOffset { index: 2, offset } if (offset[0] - 1.0).abs() < 1e-12)));
    assert!(b
        .iter()
        .any(|c| matches!(c, CanonCmd::SetG92Offset(o) if o[0] == 0.0)));
    assert!(b
        .iter()
        .any(|c| matches!(c, CanonCmd::UseToolLengthOffset(o) if o[2] == 0.5)));
}

#[test]
fn m_codes_io_wait_and_user_commands() {
    let text = "M62 P3\nM65 P1\nM66 P2 L3 Q1.5\nM66 E1 L0\nM67 E0 Q2\nM105 P1 Q2\nM2\n";
    // A user M code runs only on a machine that defines it; elsewhere it is unknown, as
    // in rs274 without an M105 program.
    let e = err(text);
    assert_eq!((e.line, e.col), (6, 1));
    assert!(e.message.contains("Unknown m code used: M105"), "{e}");
    let opts = InterpOptions {
        user_mcodes: vec![105],
        ..InterpOptions::default()
    };
    let p = load_str("t.ngc", text, &opts).unwrap();
    let b = body(&p);
    assert!(b.contains(&CanonCmd::DigitalOutput {
        index: 3,
        on: true,
        synced: true
    }));
    assert!(b.contains(&CanonCmd::DigitalOutput {
        index: 1,
        on: false,
        synced: false
    }));
    assert!(b.contains(&CanonCmd::Wait {
        index: 2,
        input: InputKind::Digital,
        kind: WaitKind::High,
        timeout_s: 1.5
    }));
    assert!(b.contains(&CanonCmd::Wait {
        index: 1,
        input: InputKind::Analog,
        kind: WaitKind::Immediate,
        timeout_s: 0.0
    }));
    assert!(b.contains(&CanonCmd::AnalogOutput {
        index: 0,
        value: 2.0,
        synced: true
    }));
    assert!(b.contains(&CanonCmd::UserMcode {
        code: 105,
        p: 1.0,
        q: 2.0
    }));
}

#[test]
fn probe_emits_straight_probe_between_probe_on_and_off() {
    let b = body(&run("G21 G38.3 Z-5 F10\nM2\n"));
    let i = b
        .iter()
        .position(|c| {
            matches!(
                c,
                CanonCmd::StraightProbe {
                    kind: ProbeKind::Toward,
                    ..
                }
            )
        })
        .unwrap();
    assert_eq!(b[i - 1], CanonCmd::Probe { on: true });
    assert_eq!(b[i + 1], CanonCmd::Probe { on: false });
}

#[test]
fn tool_table_change_and_length_offset() {
    let dir = tempfile::tempdir().unwrap();
    let tbl = dir.path().join("t.tbl");
    std::fs::write(&tbl, "T5 P1 Z10 D6 ;six mm\nT9 P2 Z20\n").unwrap();
    let opts = InterpOptions {
        tool_table: Some(tbl),
        ..InterpOptions::default()
    };
    let p = load_str("t.ngc", "G21 T9 M6 G43\nM2\n", &opts).unwrap();
    let b = body(&p);
    assert!(b.contains(&CanonCmd::SelectTool(9)));
    assert!(b.contains(&CanonCmd::ChangeTool(2)));
    assert!(b
        .iter()
        .any(|c| matches!(c, CanonCmd::UseToolLengthOffset(o) if o[2] == 20.0)));
    let e = load_str("t.ngc", "T4 M6\nM2\n", &opts).unwrap_err();
    assert!(e.message.contains("not found in the tool table"), "{e}");
}

#[test]
fn parameters_take_effect_after_the_line() {
    let p = run("#1=5\n#1=7 G21 G1 X#1 F100 #2=#1\nG1 X#2\nM2\n");
    assert_eq!(feeds(&p), vec![[5.0, 0.0, 0.0], [5.0, 0.0, 0.0]]);
}

#[test]
fn named_parameters_local_global_and_predefined() {
    let p = run(
        "o<s> sub\n#<a>=#1\n#<_g>=[#<a>*2]\no<s> endsub\n#<a>=1\no<s> call [21]\nG21 G1 X#<a> Y#<_g> Z#<_x> F1\nM2\n",
    );
    assert_eq!(feeds(&p), vec![[1.0, 42.0, 0.0]]);
    assert!(err("G0 X#<nope>\nM2\n").message.contains("#<nope>"));
    assert!(err("#<_x>=1\nM2\n").message.contains("read-only"));
}

#[test]
fn debug_and_print_substitute_parameters() {
    let b = body(&run(
        "#1=2.5\n(DEBUG, v=#1 n=#<nope>)\n(PRINT,p=#1)\n(MSG, hi)\nM2\n",
    ));
    assert!(b.contains(&CanonCmd::Message(" v=2.500000 n=######".into())));
    assert!(b.contains(&CanonCmd::Print("p=2.500000".into())));
    assert!(b.contains(&CanonCmd::Message(" hi".into())));
}

#[test]
fn loops_and_do_while_after_break_runs_fully() {
    // rs274 2.9 runs the do loop once here (see DIFFERENCES.md); hytask runs it 3 times.
    let src = "#3=0\no40 while [1]\n#3=[#3+1]\no41 if [#3 GT 3]\no40 break\no41 endif\no40 endwhile\n#4=0\no50 do\n#4=[#4+1]\no50 while [#4 LT 3]\nG21 G1 X#3 Y#4 F1\nM2\n";
    assert_eq!(feeds(&run(src)), vec![[4.0, 3.0, 0.0]]);
    let rep = run("G21 F1\no1 repeat [4]\nG91 G1 X1\no1 endrepeat\nM2\n");
    assert_eq!(feeds(&rep).len(), 4);
}

#[test]
fn subroutine_files_on_the_search_path() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("peck.ngc"),
        "o<peck> sub\nG1 Z[#1]\no<peck> endsub [#1*2]\nM2\n",
    )
    .unwrap();
    let opts = InterpOptions {
        subroutine_path: vec![dir.path().to_path_buf()],
        ..InterpOptions::default()
    };
    let p = load_str(
        "main.ngc",
        "G21 F10\no<peck> call [-3]\nG1 X#<_value>\nM2\n",
        &opts,
    )
    .unwrap();
    assert_eq!(feeds(&p), vec![[0.0, 0.0, -3.0], [-6.0, 0.0, -3.0]]);
    let sub = p
        .canon
        .iter()
        .find(|c| matches!(c.cmd, CanonCmd::StraightFeed(e) if e[2] == -3.0 && e[0] == 0.0))
        .unwrap();
    assert!(
        sub.loc.file.ends_with("peck.ngc"),
        "location names the subroutine file"
    );
    // load_file also searches the program's own directory.
    let main = dir.path().join("main.ngc");
    std::fs::write(&main, "G21 F10\no<peck> call [-1]\nM2\n").unwrap();
    assert_eq!(
        feeds(&load_file(&main, &InterpOptions::default()).unwrap()).len(),
        1
    );
    assert!(err("o<absent> call\nM2\n").message.contains("absent"));
}

#[test]
fn block_delete_switch() {
    let src = "G21\n/G0 X5\nM2\n";
    assert!(body(&run(src))
        .iter()
        .any(|c| matches!(c, CanonCmd::StraightTraverse(_))));
    let opts = InterpOptions {
        block_delete: true,
        ..InterpOptions::default()
    };
    let p = load_str("t.ngc", src, &opts).unwrap();
    assert!(!body(&p)
        .iter()
        .any(|c| matches!(c, CanonCmd::StraightTraverse(_))));
}

#[test]
fn canned_cycle_repeats_and_retract_modes() {
    let p = run("G21 G0 Z10\nG98 G81 X1 Y1 Z-2 R1 F100\nG91 G99 G81 X2 Z-3 R-9 L3\nM2\n");
    let f = feeds(&p);
    assert_eq!(f.len(), 4);
    assert_eq!(f[0], [1.0, 1.0, -2.0]);
    assert_eq!(f[3], [7.0, 1.0, -2.0]);
}

#[test]
fn cutter_compensation_offsets_the_path_and_names_the_line_of_a_gouge() {
    // G41.1 D4: radius 2, left of moves along +X: the tool runs 2 mm above them; the
    // entry move is held until the next move, G40 sends the last one.
    let p = run("G21 F100\nG0 X0 Y0\nG41.1 D4\nG1 X10 Y0\nG1 X20\nG40\nM2\n");
    assert_eq!(feeds(&p), vec![[10.0, 2.0, 0.0], [20.0, 2.0, 0.0]]);
    // A concave corner the tool cannot reach: refused on the move that makes it.
    let e = err("G21 F100\nG0 X0 Y0\nG41.1 D4\nG1 X10 Y0\nG1 X9 Y1\nG1 X9 Y10\nM2\n");
    assert_eq!((e.line, e.col), (6, 1), "{e}");
    assert!(e.message.contains("concave corner"), "{e}");
    assert!(e.message.contains("tool radius 2.0000"), "{e}");
}

#[test]
fn unsupported_g_codes_say_their_name() {
    let e = err("G21 F100 S100 M3\nG87 X1 Z-1 R1 I1 J1 K1\nM2\n");
    assert_eq!((e.line, e.col), (2, 1), "{e}");
    assert!(
        e.message
            .starts_with("G87 (back boring cycle) is not supported"),
        "{e}"
    );
}

#[test]
fn arcs_are_modal_like_g0_and_g1() {
    let p = run("G21 F100\nG0 X10 Y0\nG3 X0 Y10 I-10 J0\nX-10 Y0 I0 J-10\nX0 Y-10 Z-1 R10\nM2\n");
    let arcs: Vec<_> = body(&p)
        .into_iter()
        .filter_map(|c| match c {
            CanonCmd::ArcFeed {
                first_end,
                second_end,
                first_center,
                second_center,
                rotation,
                ..
            } => Some([
                first_end,
                second_end,
                first_center,
                second_center,
                rotation.into(),
            ]),
            _ => None,
        })
        .collect();
    assert_eq!(arcs.len(), 3);
    assert_eq!(arcs[1], [-10.0, 0.0, 0.0, 0.0, 1.0]);
    assert!((arcs[2][0]).abs() < 1e-12 && (arcs[2][1] + 10.0).abs() < 1e-12);
    // The words of an arc still need a motion that uses them.
    assert!(err("G21 F100\nG0 X10\nG3 X0 Y10 I-10 J0\nG1 X1 I1\nM2\n")
        .message
        .starts_with("I word with no G2"));
}

#[test]
fn g53_and_homes_are_not_rotated_by_g10_r() {
    let p = run("G21\nG10 L2 P1 R45\nG53 G0 X10 Y0\nG28.1\nG0 X0 Y0\nG28\nM2\n");
    let ends: Vec<[f64; 2]> = body(&p)
        .into_iter()
        .filter_map(|c| match c {
            CanonCmd::StraightTraverse(e) => Some([e[0], e[1]]),
            _ => None,
        })
        .collect();
    // Program (7.07, -7.07) turned by 45 degrees is machine (10, 0).
    let h = 50f64.sqrt();
    let near = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9;
    assert!(near(ends[0], [h, -h]), "{ends:?}");
    // G28.1 stored machine (10, 0); G28 goes back there through the rotated frame.
    assert!(near(ends[3], [h, -h]), "{ends:?}");
}

#[test]
fn o_word_forms_that_cam_and_people_write() {
    let p = run(concat!(
        "O32123 (program number)\n",
        "o100 sub\no110 if [#1 GT 5]\no110 return\no110 endif\nG0 X#1\no100 endsub\n",
        "#2 = 10\no[#2 * 10] call [3] (then) [4]\no100 call [7]\nM2\n"
    ));
    let xs: Vec<f64> = body(&p)
        .into_iter()
        .filter_map(|c| match c {
            CanonCmd::StraightTraverse(e) => Some(e[0]),
            _ => None,
        })
        .collect();
    assert_eq!(xs, vec![3.0]);
    let e = err("o100 sub\n  o200 sub\n  o200 endsub\no100 endsub\nM2\n");
    assert_eq!((e.line, e.col), (2, 3));
    assert!(e.message.starts_with("Nested subroutine definition"), "{e}");
}

#[test]
fn abort_comment_stops_the_program_with_its_text() {
    let e = err("G0 X1\n(abort, tool not measured)\nG0 X2\nM2\n");
    assert_eq!((e.line, e.col), (2, 1));
    assert_eq!(e.message, "Program aborted: tool not measured");
}

#[test]
fn each_limit_has_its_own_error() {
    let tight = InterpOptions {
        limits: Limits {
            max_call_depth: 5,
            max_expr_depth: 8,
            max_loop_iterations: 100,
            max_blocks: 10_000,
            max_file_bytes: 10_000,
            max_line_len: 200,
            max_lines: 500,
            max_canon: 1000,
        },
        ..InterpOptions::default()
    };
    let m = |s: &str| err_with(s, &tight).message;
    assert!(m("o<r> sub\no<r> call\no<r> endsub\no<r> call\nM2\n").contains("nested too deeply"));
    assert!(m("#1=[[[[[[[[[[1]]]]]]]]]]\nM2\n").contains("nested too deeply"));
    assert!(m("o1 while [1]\no1 endwhile\nM2\n").contains("exceeded 100 iterations"));
    let many = "o1 repeat [90]\no2 repeat [90]\no2 endrepeat\no1 endrepeat\nM2\n";
    assert!(m(many).contains("too many blocks"));
    assert!(m(&"G0 X1\n".repeat(3000)).contains("too large"));
    assert!(m(&format!("G0 X1 ({})\nM2\n", "x".repeat(300))).contains("Line too long"));
    assert!(m(&"\n".repeat(600)).contains("too long"));
    let canon = "o1 repeat [90]\nG0 X1\nG0 X2\nG0 X3\nG0 X4\nG0 X5\nG0 X6\nG0 X7\nG0 X8\nG0 X9\nG0 X0\nG0 X1\nG0 X2\no1 endrepeat\nM2\n";
    assert!(m(canon).contains("too many canonical commands"));
}

#[test]
fn expressions_use_linuxcnc_precedence_and_functions() {
    let p = run("G21 G1 F1 X[1+2*3**2 MOD 4] Y[ATAN[1]/[1]] Z[ROUND[-2.5]]\nM2\n");
    assert_eq!(feeds(&p), vec![[3.0, 45.0, -3.0]]);
    assert!(err("#1=[1/0]\nM2\n").message.contains("divide by zero"));
}

#[test]
fn initial_position_is_where_the_program_starts() {
    let opts = InterpOptions {
        initial_position: Some([25.4, 50.8, -12.7, 90.0, 0.0, 0.0]),
        initial_units: hytask::gcode::LengthUnits::Inches,
        ..InterpOptions::default()
    };
    let p = load_str("start.ngc", "G91 G1 X1 F10\nG90 G0 Z0\nM2\n", &opts).unwrap();
    let moves: Vec<[f64; 9]> = p
        .canon
        .iter()
        .filter_map(|c| match c.cmd {
            CanonCmd::StraightFeed(e) | CanonCmd::StraightTraverse(e) => Some(e),
            _ => None,
        })
        .collect();
    // In inches: start (1, 2, -0.5), A stays 90 deg; G91 X1 ends at X2, then Z0.
    assert_eq!(&moves[0][..4], &[2.0, 2.0, -0.5, 90.0]);
    assert_eq!(&moves[1][..4], &[2.0, 2.0, 0.0, 90.0]);
    // Without it, rs274's behaviour: the program starts at 0.
    let p = load_str("zero.ngc", "G91 G1 X1 F10\nM2\n", &InterpOptions::default()).unwrap();
    assert!(p
        .canon
        .iter()
        .any(|c| matches!(c.cmd, CanonCmd::StraightFeed(e) if e[0] == 1.0 && e[1] == 0.0)));
}

#[test]
fn mdi_mode_needs_no_program_end_and_keeps_modes() {
    let mdi = InterpOptions {
        mdi: true,
        ..InterpOptions::default()
    };
    let p = load_str("mdi", "G91 G1 X2 F100\n", &mdi).unwrap();
    assert!(p
        .canon
        .iter()
        .any(|c| matches!(c.cmd, CanonCmd::StraightFeed(e) if e[0] == 2.0)));
    // No M2 side effects: the spindle is not stopped, the feed rate not reset.
    assert!(!p
        .canon
        .iter()
        .any(|c| matches!(c.cmd, CanonCmd::StopSpindle | CanonCmd::ProgramEnd)));
    // A program (not MDI) still needs its end.
    let e = err("G1 X2 F100\n");
    assert!(e.message.contains("program end"), "{e}");
    let e = err_with("G1 X1 G0\n", &mdi);
    assert_eq!((e.file.as_str(), e.line), ("t.ngc", 1));
}

/// End to end through the planner: after `G10 L2 P1 R45`, `G53 G0 X10 Y0` reaches machine
/// (10, 0) and `G28` the stored machine home, not the point turned by 45 degrees.
#[test]
fn machine_positions_survive_an_xy_rotation_through_the_planner() {
    let cfg = hytask::motion::MotionConfig::default();
    let end = |text: &str| {
        let p = run(text);
        hytask::motion::plan(&p.canon, &cfg).unwrap().end_mm
    };
    let e = end("G21\nG10 L2 P1 X1 Y2 R45\nG53 G0 X10 Y0\nM2\n");
    assert!((e[0] - 10.0).abs() < 1e-9 && e[1].abs() < 1e-9, "{e:?}");
    let e = end("G21\nG0 X3 Y4\nG28.1\nG10 L2 P1 X1 Y2 R45\nG0 X7 Y-2\nG28\nM2\n");
    assert!(
        (e[0] - 3.0).abs() < 1e-9 && (e[1] - 4.0).abs() < 1e-9,
        "{e:?}"
    );
}

/// Bytes that are not UTF-8 are named with their line and column: a Latin-1 comment still
/// runs (as in rs274), a bad byte in a word is refused saying what it is.
#[test]
fn bytes_that_are_not_utf8_are_located() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("latin1.ngc");
    std::fs::write(&f, b"G21 (caf\xe9)\nG0 X1\nG0 X\xff2\nM2\n").unwrap();
    let e = load_file(&f, &InterpOptions::default()).unwrap_err();
    assert_eq!((e.line, e.col), (3, 5), "{e}");
    assert!(e.message.contains("not UTF-8"), "{e}");
    std::fs::write(&f, b"G21 (caf\xe9)\nG0 X1\nM2\n").unwrap();
    assert!(load_file(&f, &InterpOptions::default()).is_ok());
}

#[test]
fn fanuc_m98_repeats_share_parameters_and_l0_calls_nothing() {
    // L3: three runs of O10, each one step further (#1 is shared with the caller);
    // L0: no run at all, and the next line runs once. (`G1 F100` alone is a zero-length
    // feed, as in rs274.)
    let p = run("#1=0\nG1 F100\nM98 P10 L3\nM98 P11 L0\nG1 Y#1\nM2\nO10\n#1=[#1+1]\nG1 X#1\nM99\nO11\nG0 Z9\nM99\n");
    assert_eq!(
        feeds(&p),
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [3.0, 0.0, 0.0],
            [3.0, 3.0, 0.0]
        ]
    );
    assert!(!body(&p)
        .iter()
        .any(|c| matches!(c, CanonCmd::StraightTraverse(_))));
    // Where the subprogram's lines say they came from: line 9 (G1 X#1), three times.
    let lines: Vec<u32> = p
        .canon
        .iter()
        .filter(|c| matches!(c.cmd, CanonCmd::StraightFeed(_)))
        .map(|c| c.loc.line)
        .collect();
    assert_eq!(lines, vec![2, 9, 9, 9, 5]);
}

#[test]
fn fanuc_m98_errors_name_the_line() {
    // rs274 names the line its search for the subprogram stopped at: the end of the file
    // (its last line, or the closing %), or a definition of the wrong kind; the message
    // names the call's line. (program, error line, every text the message must contain)
    let cases: [(&str, u32, &[&str]); 7] = [
        ("G21\nM98 P77\nM2\n", 3, &["O77", "line 2"]),
        ("%\nM98 P1\nM30\n%\nO1\nM99\n", 4, &[]),
        (
            "%\nM98 P1\nM30\nO1 sub\nO1 endsub\n%\n",
            4,
            &["must be called with 'O.... call'"],
        ),
        (
            "%\nO1 call\nM30\nO1\nM99\n%\n",
            4,
            &["must be called with 'M98'"],
        ),
        ("o<nosub> call\nM2\n(end)\n", 3, &["o<nosub>", "line 1"]),
        // a definition a call found ahead, which the program then runs into
        (
            "O1\nO2 call\nG0 X1\nO2 sub\nG0 Z3\nO2 endsub\nG0 X2\nM2\n",
            4,
            &["illegal location"],
        ),
        (
            "M98 P10\nM2\nO10\nG0 X1 M99\n",
            4,
            &["M99 must begin its line"],
        ),
    ];
    for (program, line, texts) in cases {
        let e = err(program);
        assert_eq!(e.line, line, "{program:?}: {}", e.message);
        for t in texts {
            assert!(e.message.contains(t), "{program:?}: {}", e.message);
        }
    }
    assert_eq!(err("G21\nM98 P77\nM2\n").col, 1);
}

/// The machine's ini values: `[RS274NGC] ORIENT_OFFSET` is added to every M19 angle,
/// unwrapped (rs274 -i with ORIENT_OFFSET = 42 prints 87, 42 and 392 for these), and an
/// `#<_ini[…]>` value is read-only once there is an ini file.
#[test]
fn ini_orient_offset_and_read_only_ini_values() {
    let opts = InterpOptions {
        ini: std::sync::Arc::new(hytask::gcode::IniValues::parse(
            "[RS274NGC]\nORIENT_OFFSET = 42.0\n[VARS]\nTOOLCHANGE_X = 10\n",
        )),
        ..InterpOptions::default()
    };
    let p = load_str("t.ngc", "M19 R45 Q2\nM19 P1\nM19 R350\nM2\n", &opts).unwrap();
    let angles: Vec<f64> = body(&p)
        .iter()
        .filter_map(|c| match c {
            CanonCmd::OrientSpindle { angle, .. } => Some(*angle),
            _ => None,
        })
        .collect();
    assert_eq!(angles, vec![87.0, 42.0, 392.0]);
    let e = err_with("#<_ini[vars]toolchange_x> = 3\nM2\n", &opts);
    assert!(e.to_string().contains("read-only"), "{e}");
    // Without an ini file (rs274 standalone) it may be set.
    run("#<_ini[vars]toolchange_x> = 3\nM2\n");
}

/// Embedded Python (LinuxCNC's `[PYTHON]` and `;py,`): a missing interpreter is an error on
/// the line that needed it, not a panic or a silent skip; a Python procedure's moves and
/// printed lines arrive as commands; a program without Python enabled never starts it.
#[test]
fn embedded_python_errors_name_the_line_and_moves_arrive_as_commands() {
    use hytask::gcode::python::PythonConfig;
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("top.py"), "import oword\n").unwrap();
    std::fs::write(
        dir.path().join("oword.py"),
        "import emccanon\n\
         def go(self, x):\n    print('going to', x)\n    \
         emccanon.STRAIGHT_FEED(1, x, 2, 3, 0, 0, 0, 0, 0, 0)\n    return x * 2\n",
    )
    .unwrap();
    let ini = "[PYTHON]\nPATH_PREPEND = .\nTOPLEVEL = top.py\n";
    let cfg = PythonConfig::from_ini(ini, dir.path()).unwrap();
    let opts = InterpOptions {
        python: Some(cfg.clone()),
        ..InterpOptions::default()
    };
    let p = load_str(
        "t.ngc",
        "G0 X1\no<go> call [4]\n#<r> = #<_value>\nG1 X#<r> F10\nM2\n",
        &opts,
    )
    .unwrap();
    let b = body(&p);
    assert!(b.contains(&CanonCmd::Print("going to 4.0".into())), "{b:?}");
    assert!(b
        .iter()
        .any(|c| matches!(c, CanonCmd::StraightFeed(e) if e[..3] == [4.0, 2.0, 3.0])));
    assert_eq!(feeds(&p).last(), Some(&[8.0, 0.0, 0.0]));

    let missing = InterpOptions {
        python: Some(PythonConfig {
            python: "/nonexistent/python3".into(),
            ..cfg
        }),
        ..InterpOptions::default()
    };
    let e = err_with("G0 X1\n\no<go> call [4]\nM2\n", &missing);
    assert_eq!((e.line, e.file.as_str()), (3, "t.ngc"));
    assert!(
        e.message.contains("cannot start the Python interpreter"),
        "{e}"
    );

    let bare = InterpOptions {
        python: Some(PythonConfig::bare()),
        ..InterpOptions::default()
    };
    let e = err_with("G0 X1\n;py,assert 1 == 2, 'one is not two'\nM2\n", &bare);
    assert_eq!(e.line, 2);
    assert!(e.message.contains("AssertionError: one is not two"), "{e}");
    // Without Python enabled (the default, and the daemon's), a program alone runs no code
    // on the host: `;py,` and `(py,…)` are ordinary comments.
    let marker = dir.path().join("ran");
    let escape = format!(
        "G0 X1\n;py,open('{}', 'w').close(); assert False\n(py,assert False)\nG0 X2\nM2\n",
        marker.display()
    );
    let p = run(&escape);
    assert!(body(&p)
        .iter()
        .any(|c| matches!(c, CanonCmd::StraightTraverse(e) if e[0] == 2.0)));
    assert!(!marker.exists(), "Python ran");
    // The same program with Python enabled runs it (the check above can fail).
    let e = err_with(&escape, &bare);
    assert_eq!(e.line, 2);
    assert!(marker.exists());
    // without [PYTHON], an o-call of a name Python would have is an ordinary missing sub
    let e = err("o<go> call\nM2\n");
    assert!(e.message.contains("Failed to find subroutine o<go>"), "{e}");
}

/// A Python procedure that never returns does not hold a cancelled interpretation: the
/// cancel flag is polled while Python runs, and the child is killed.
#[test]
fn cancel_stops_a_python_procedure_that_never_returns() {
    use hytask::gcode::python::PythonConfig;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("top.py"), "import oword\n").unwrap();
    std::fs::write(
        dir.path().join("oword.py"),
        "def spin(self):\n    while True:\n        pass\n",
    )
    .unwrap();
    let ini = "[PYTHON]\nPATH_PREPEND = .\nTOPLEVEL = top.py\n";
    let cancel = Arc::new(AtomicBool::new(false));
    let opts = InterpOptions {
        python: PythonConfig::from_ini(ini, dir.path()),
        cancel: Some(cancel.clone()),
        ..InterpOptions::default()
    };
    let stop = std::thread::spawn(move || {
        std::thread::sleep(std::time::Duration::from_millis(500));
        cancel.store(true, Ordering::Relaxed);
    });
    let t0 = std::time::Instant::now();
    let e = err_with("G0 X1\no<spin> call\nM2\n", &opts);
    stop.join().unwrap();
    assert_eq!(e.line, 2);
    assert!(e.message.contains("cancelled"), "{e}");
    assert!(t0.elapsed() < std::time::Duration::from_secs(10));
}
