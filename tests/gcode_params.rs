//! Persistent parameters (the var file) and `#<_ini[section]name>` through the machine
//! configuration, as the daemon uses them (issue 13). The var-file format against rs274 is
//! checked by the differential suite (`corpus/vars_*.ngc` with their `.var` files).
#![allow(clippy::unwrap_used)]

use hytask::gcode::{load_str, load_str_persistent, CanonCmd, VarFile};
use hytask::machine::job::interp_options;
use std::sync::Arc;

fn sim_with(extra: &str) -> hytask::config::MachineConfig {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.toml")).unwrap();
    hytask::config::parse(&format!("{text}\n{extra}"), "sim+gcode").unwrap()
}

fn traverses(canon: &[hytask::gcode::Canon]) -> Vec<[f64; 3]> {
    canon
        .iter()
        .filter_map(|c| match c.cmd {
            CanonCmd::StraightTraverse(p) => Some([p[0], p[1], p[2]]),
            _ => None,
        })
        .collect()
}

#[test]
fn ini_names_map_to_the_axis_limits_and_the_free_table() {
    let cfg = sim_with("[gcode.ini.probe]\nfeed = 42.5\n");
    let opts = interp_options(&cfg);
    let p = load_str(
        "t.ngc",
        "G21 G0 X#<_ini[axis_x]max_velocity> Y#<_ini[PROBE]FEED> Z#<_ini[axis_z]max_velocity>\nM2\n",
        &opts,
    )
    .unwrap();
    assert_eq!(traverses(&p.canon), vec![[100.0, 42.5, 50.0]]);
    // EXISTS tells configured from unknown names.
    let p = load_str(
        "t.ngc",
        "G0 X[EXISTS[#<_ini[axis_x]nope>]] Y[EXISTS[#<_ini[joint_1]max_velocity>]]\nM2\n",
        &opts,
    )
    .unwrap();
    assert_eq!(traverses(&p.canon), vec![[0.0, 1.0, 0.0]]);
}

#[test]
fn an_unknown_ini_name_is_an_error_naming_it() {
    let opts = interp_options(&sim_with(""));
    let e = load_str("t.ngc", "G0 X1\nG0 X#<_ini[axis_x]nope>\nM2\n", &opts).unwrap_err();
    assert_eq!(e.line, 2);
    assert!(e.message.contains("#<_ini[axis_x]nope>"), "{e}");
}

#[test]
fn a_bad_ini_entry_is_a_config_error_naming_the_key() {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.toml")).unwrap();
    let e = hytask::config::parse(&format!("{text}\n[gcode.ini.a]\n\"x>y\" = 1\n"), "m.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("gcode.ini.a.x>y"), "{e}");
}

#[test]
fn a_job_starts_from_the_var_file_and_leaves_the_next_one_its_offsets() {
    // G55 active with an offset, from the file; the program moves the G55 origin and ends
    // without M2 (which would go back to G54): the next job starts there.
    let mut opts = interp_options(&sim_with(""));
    opts.parameters = Some(Arc::new(
        VarFile::parse("m.var", "5220\t2\n5241\t10\n5242\t20\n").unwrap(),
    ));
    let (p, after) =
        load_str_persistent("a.ngc", "%\nG0 X1 Y1\nG10 L2 P2 X30\n%\n", &opts).unwrap();
    assert!(p.canon.iter().any(|c| matches!(
        c.cmd,
        CanonCmd::SetG5xOffset { index: 2, offset } if offset[0] == 10.0 && offset[1] == 20.0
    )));
    let get = |v: &VarFile, n: u16| v.values.iter().find(|x| x.0 == n).map(|x| x.1);
    assert_eq!(get(&after, 5220), Some(2.0));
    assert_eq!(get(&after, 5241), Some(30.0));
    assert_eq!(
        get(&after, 5390),
        Some(0.0),
        "every required number is saved"
    );
    opts.parameters = Some(Arc::new(after));
    let (p, _) = load_str_persistent("b.ngc", "%\nG0 X0 Y0\n%\n", &opts).unwrap();
    assert!(p.canon.iter().any(|c| matches!(
        c.cmd,
        CanonCmd::SetG5xOffset { index: 2, offset } if offset[0] == 30.0
    )));
}

#[test]
fn a_relative_var_file_is_resolved_against_the_config_directory() {
    let dir = std::env::temp_dir().join(format!("hytask-gcode-params-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.toml")).unwrap();
    let path = dir.join("m.toml");
    std::fs::write(&path, format!("{text}\n[gcode]\nvar_file = \"m.var\"\n")).unwrap();
    let cfg = hytask::config::load(&path).unwrap();
    assert_eq!(
        cfg.gcode.var_file.as_deref(),
        Some(dir.join("m.var").as_path())
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_prepared_job_carries_the_parameters_it_leaves_for_the_daemon_to_save() {
    // The daemon commits `PreparedJob::parameters` when the job has run to its end; every
    // way a job is prepared (streamed, probing, MDI) must fill it in.
    use hytask::machine::api::JobSource;
    use hytask::machine::job::{motion_config, prepare, prepare_mdi};
    let cfg = sim_with("");
    let mut opts = interp_options(&cfg);
    opts.parameters = Some(Arc::new(VarFile::parse("m.var", "100\t1\n").unwrap()));
    let motion = motion_config(&cfg);
    let start = [10.0, 10.0, -5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let get = |v: &VarFile, n: u16| v.values.iter().find(|x| x.0 == n).map(|x| x.1);
    let src = |text: &str| JobSource {
        path: None,
        text: Some(text.into()),
        name: None,
    };
    let streamed = prepare(
        &src("G21 G10 L2 P1 X5\n#100=2\nG0 X20\nM2\n"),
        &opts,
        &motion,
        start,
    )
    .unwrap();
    let v = streamed.parameters.unwrap();
    assert_eq!((get(&v, 5221), get(&v, 100)), (Some(5.0), Some(2.0)));
    let probing = prepare(
        &src("G21 G10 L2 P2 Y7\nG38.2 Z-20 F100\nG0 Z0\nM2\n"),
        &opts,
        &motion,
        start,
    )
    .unwrap();
    assert!(probing.probing.is_some());
    assert_eq!(get(probing.parameters.as_ref().unwrap(), 5242), Some(7.0));
    let mdi = prepare_mdi("G21 G10 L2 P3 Z-3", &opts, &motion, start).unwrap();
    assert_eq!(get(mdi.parameters.as_ref().unwrap(), 5263), Some(-3.0));
}
