//! Every kind of configuration error names its section and key; validation reports all
//! problems at once.
#![allow(clippy::unwrap_used)]

use hytask::config::{self, ConfigError, BUILTIN_SIM_TOML};

/// The built-in sim file with `(from, to)` replacements applied (each must match).
fn edited(edits: &[(&str, &str)]) -> String {
    let mut text = BUILTIN_SIM_TOML.to_string();
    for (from, to) in edits {
        assert!(text.contains(from), "edit target {from:?} not in sim.toml");
        text = text.replacen(from, to, 1);
    }
    text
}

/// Validation issues, as "key: message" lines.
fn issues(edits: &[(&str, &str)]) -> Vec<String> {
    match config::parse(&edited(edits), "test.toml") {
        Err(ConfigError::Invalid { issues, .. }) => {
            issues.iter().map(ToString::to_string).collect()
        }
        other => panic!("expected validation errors, got {other:?}"),
    }
}

/// The (key, message) of a deserialisation error.
fn parse_error(edits: &[(&str, &str)]) -> (String, String) {
    match config::parse(&edited(edits), "test.toml") {
        Err(ConfigError::Parse { key, message, .. }) => (key, message),
        other => panic!("expected a parse error, got {other:?}"),
    }
}

fn assert_has(issues: &[String], expected: &str) {
    assert!(
        issues.iter().any(|i| i == expected),
        "missing {expected:?} in:\n{}",
        issues.join("\n")
    );
}

#[test]
fn range_errors_name_section_key_and_value() {
    let found = issues(&[
        ("max_velocity = 100.0\nmax_acceleration = 1000.0\nmax_jerk = 20000.0\nfollowing_error_limit = 1.0\nhome = { method = \"switch\", position = 300.0, velocity = 20.0, latch_velocity = 2.0, sequence = 1 }\n\n[[axis]]\nname = \"Y\"\ndrive = \"y\"\nmin_limit = 0.0\nmax_limit = 300.0\nmax_velocity = 100.0",
         "max_velocity = 100.0\nmax_acceleration = 1000.0\nmax_jerk = 20000.0\nfollowing_error_limit = 1.0\nhome = { method = \"switch\", position = 300.0, velocity = 20.0, latch_velocity = 2.0, sequence = 1 }\n\n[[axis]]\nname = \"Y\"\ndrive = \"y\"\nmin_limit = 0.0\nmax_limit = 300.0\nmax_velocity = -5"),
    ]);
    assert_has(&found, "axis[1] (Y).max_velocity: must be > 0, got -5");
}

#[test]
fn each_section_reports_its_own_keys() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "name = \"sim-mill\"",
            "name = \"sim mill\"",
            "machine.name: \"sim mill\": use only letters, digits, '_' and '-'",
        ),
        (
            "period_us = 1000",
            "period_us = 10",
            "thread[0] (servo).period_us: must be in 50..=1000000, got 10",
        ),
        (
            "priority = 80",
            "priority = 0",
            "thread[0] (servo).priority: must be in 1..=99, got 0",
        ),
        (
            "max_limit = 300.0",
            "max_limit = -1.0",
            "axis[0] (X).max_limit: must be greater than min_limit (0), got -1",
        ),
        (
            "max_acceleration = 1000.0",
            "max_acceleration = 0.0",
            "axis[0] (X).max_acceleration: must be > 0, got 0",
        ),
        (
            "max_jerk = 20000.0",
            "max_jerk = -1.0",
            "axis[0] (X).max_jerk: must be > 0, got -1",
        ),
        (
            "following_error_limit = 1.0",
            "following_error_limit = 0.0",
            "axis[0] (X).following_error_limit: must be > 0, got 0",
        ),
        (
            "drive = \"x\"\n",
            "drive = \"x\"\nscale = 0.0\n",
            "axis[0] (X).scale: must be a non-zero finite number, got 0",
        ),
        (
            "position = 300.0, velocity = 20.0",
            "position = 400.0, velocity = 20.0",
            "axis[0] (X).home.position: must be within the soft limits 0..=300, got 400",
        ),
        (
            "velocity = 20.0, latch_velocity = 2.0",
            "velocity = 20.0, latch_velocity = 30.0",
            "axis[0] (X).home.latch_velocity: must be > 0 and at most |home.velocity| (20), got 30",
        ),
        (
            "lag_s = 0.005   ",
            "lag_s = 2.0   ",
            "drive[0] (x).sim.lag_s: must be in 0..=1, got 2",
        ),
        (
            "negative_limit = -3.0\npositive_limit = 306.0",
            "negative_limit = 400.0\npositive_limit = 306.0",
            "drive[0] (x).sim.positive_limit: must be above negative_limit (400), got 306",
        ),
        (
            "max_rpm = 24000.0",
            "max_rpm = 0.0",
            "spindle.max_rpm: must be > 0, got 0",
        ),
        (
            "min_rpm = 1000.0",
            "min_rpm = 30000.0",
            "spindle.min_rpm: must be below max_rpm (24000), got 30000",
        ),
        (
            "mode = \"0660\"",
            "mode = \"0666\"",
            "control.mode: 0666 gives other users access to the machine; clear the last digit",
        ),
        (
            "lookahead = 200",
            "lookahead = 1",
            "motion.lookahead: must be in 2..=10000, got 1",
        ),
        (
            "rapid_override = 1.0",
            "rapid_override = 1.5",
            "motion.rapid_override: must be in (0, 1], got 1.5",
        ),
        (
            "g64_tolerance = 0.01",
            "g64_tolerance = -0.1",
            "motion.g64_tolerance: must be >= 0, got -0.1",
        ),
        (
            "overrun_storm_count = 50",
            "overrun_storm_count = 0",
            "safety.overrun_storm_count: must be >= 1, got 0",
        ),
    ];
    for (from, to, expected) in cases {
        assert_has(&issues(&[(from, to)]), expected);
    }
}

#[test]
fn unknown_keys_are_rejected_with_their_path() {
    let (key, msg) = parse_error(&[(
        "following_error_limit = 1.0\n",
        "following_error_limit = 1.0\nmax_speed = 3\n",
    )]);
    assert_eq!(key, "axis[0].max_speed");
    assert!(msg.contains("unknown field `max_speed`"), "{msg}");
    assert!(msg.contains("line "), "points at the line: {msg}");

    let (key, _) = parse_error(&[("lag_s = 0.005   ", "lagg_s = 0.005   ")]);
    assert_eq!(key, "drive[0].sim.lagg_s");

    let (key, _) = parse_error(&[("[logging]\n", "[logging]\ncolour = true\n")]);
    assert_eq!(key, "logging.colour");

    let (key, msg) = parse_error(&[("[machine]\n", "[mashine]\nx = 1\n[machine]\n")]);
    assert_eq!(key, "mashine");
    assert!(msg.contains("unknown field `mashine`"), "{msg}");
}

#[test]
fn wrong_types_missing_keys_and_bad_enums_name_their_key() {
    let (key, msg) = parse_error(&[("max_rpm = 24000.0", "max_rpm = \"fast\"")]);
    assert_eq!(key, "spindle.max_rpm");
    assert!(msg.contains("invalid type"), "{msg}");

    let (key, msg) = parse_error(&[("name = \"Y\"", "name = \"Q\"")]);
    assert_eq!(key, "axis[1].name");
    assert!(msg.contains("unknown variant `Q`"), "{msg}");

    let (key, msg) = parse_error(&[("following_error_limit = 1.0\n", "")]);
    assert_eq!(key, "axis[0]");
    assert!(
        msg.contains("missing field `following_error_limit`"),
        "{msg}"
    );

    let (key, msg) = parse_error(&[("backend = \"sim\"", "backend = \"ethercat\"")]);
    assert_eq!(key, "drive[0].backend");
    assert!(msg.contains("unknown variant `ethercat`"), "{msg}");

    let (key, msg) = parse_error(&[("mode = \"0660\"", "mode = \"rw\"")]);
    assert_eq!(key, "control.mode");
    assert!(msg.contains("octal file mode"), "{msg}");
}

#[test]
fn malformed_toml_is_a_parse_error_with_a_line() {
    let (_, msg) = parse_error(&[("[logging]", "[logging")]);
    assert!(msg.contains("line "), "{msg}");
}

#[test]
fn cross_references_are_checked() {
    let found = issues(&[
        ("drive = \"z\"", "drive = \"spindle\""),
        ("estop_input = \"estop\"", "estop_input = \"e_stop\""),
        (
            "flood_output = \"coolant_flood\"",
            "flood_output = \"probe\"",
        ),
        ("servo_thread = \"servo\"", "servo_thread = \"fast\""),
        ("probe_input = \"probe\"", "probe_input = \"coolant_mist\""),
    ]);
    assert_has(
        &found,
        "axis[2] (Z).drive: no [[drive]] named \"spindle\" (drives: x, y, z)",
    );
    assert_has(
        &found,
        "safety.estop_input: no digital input named \"e_stop\" in any [[io]]",
    );
    assert_has(
        &found,
        "coolant.flood_output: \"probe\" is a digital input, expected a digital output",
    );
    assert_has(
        &found,
        "motion.servo_thread: no [[thread]] named \"fast\" (threads: servo, plc)",
    );
    assert_has(
        &found,
        "motion.probe_input: \"coolant_mist\" is a digital output, expected a digital input",
    );
}

#[test]
fn names_must_be_unique() {
    let found = issues(&[
        ("name = \"Y\"", "name = \"X\""),
        ("{ name = \"probe\" }", "{ name = \"estop\" }"),
        ("name = \"plc\"", "name = \"servo\""),
    ]);
    assert_has(&found, "axis[1] (X).name: duplicate of axis[0] (X)");
    assert_has(&found, "io[0] (panel).digital_inputs[1].name: \"estop\" is already used by io[0] (panel).digital_inputs[0]: channel names are machine-wide");
    assert_has(
        &found,
        "thread[1] (servo).name: duplicate of thread[0] (servo)",
    );

    let found = issues(&[("drive = \"y\"", "drive = \"x\"")]);
    assert_has(
        &found,
        "axis[1] (Y).drive: drive \"x\" already moves axis[0] (X)",
    );
}

#[test]
fn shorter_periods_must_not_have_lower_priority() {
    let found = issues(&[("priority = 60", "priority = 85")]);
    assert_has(&found, "thread[0] (servo).priority: 80 is lower than thread[1] (plc)'s 85 although its period (1000 us) is shorter than 10000 us; shorter periods need higher (or equal) priority");
    // Equal priorities are allowed (the faster thread is still not delayed by a lower one).
    assert!(config::parse(&edited(&[("priority = 60", "priority = 80")]), "t").is_ok());
    let found = issues(&[(
        "period_us = 10000\npriority = 60",
        "period_us = 1000\npriority = 80",
    )]);
    assert_has(&found, "thread[1] (plc).priority: same period and priority as thread[0] (servo): one thread per (period, priority); merge them");
}

#[test]
fn backend_sections_must_match_the_backend() {
    let found = issues(&[(
        "name = \"x\"\nbackend = \"sim\"",
        "name = \"x\"\nbackend = \"canopen\"",
    )]);
    assert_has(
        &found,
        "drive[0] (x).sim: only used with backend = \"sim\" (backend is \"canopen\")",
    );
    assert_has(
        &found,
        "drive[0] (x).canopen: required with backend = \"canopen\" (interface, node_id)",
    );

    let found = issues(&[(
        "backend = \"sim\"\ndigital_inputs",
        "backend = \"sim\"\naddress = \"10.0.0.1:502\"\ndigital_inputs",
    )]);
    assert_has(
        &found,
        "io[0] (panel).address: not used with backend = \"sim\"",
    );

    let found = issues(&[(
        "backend = \"sim\"\ndigital_inputs",
        "backend = \"modbus_tcp\"\naddress = \"10.0.0.1\"\ndigital_inputs",
    )]);
    assert_has(
        &found,
        "io[0] (panel).address: must be \"host:port\" with a port in 1..=65535, got \"10.0.0.1\"",
    );
}

#[test]
fn canopen_settings_are_checked() {
    let canopen = |node: u8, iface: &str| {
        format!("name = \"x\"\nbackend = \"canopen\"\ncanopen = {{ interface = \"{iface}\", node_id = {node} }}\n[drive.sim]")
    };
    // Drive x becomes a CANopen drive with an invalid node id, keeping its [drive.sim].
    let text = edited(&[(
        "name = \"x\"\nbackend = \"sim\"\n[drive.sim]",
        &canopen(0, "can0"),
    )]);
    let err = config::parse(&text, "t").unwrap_err();
    let all: Vec<String> = err.issues().iter().map(ToString::to_string).collect();
    assert_has(
        &all,
        "drive[0] (x).canopen.node_id: must be in 1..=127, got 0",
    );
    assert_has(
        &all,
        "drive[0] (x).sim: only used with backend = \"sim\" (backend is \"canopen\")",
    );
}

#[test]
fn duplicate_canopen_nodes_on_one_interface_are_refused() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/example-canopen.toml"
    ))
    .unwrap();
    let text = text.replacen("node_id = 2", "node_id = 1", 1);
    let err = config::parse(&text, "t").unwrap_err();
    let all: Vec<String> = err.issues().iter().map(ToString::to_string).collect();
    assert_has(
        &all,
        "drive[1] (y-servo).canopen.node_id: node 1 on can0 is already drive[0] (x-servo)",
    );
}

#[test]
fn homing_method_needs_the_simulated_switch() {
    let found = issues(&[("home_switch = { min = 300.5, max = 305.0 }\n", "")]);
    assert_has(
        &found,
        "drive[0] (x).sim.home_switch: required: axis X homes with method = \"switch\"",
    );
}

#[test]
fn scara_kinematics_needs_its_link_lengths() {
    let found = issues(&[("kinematics = \"identity\"", "kinematics = \"scara\"")]);
    assert_has(
        &found,
        "machine.scara: required with kinematics = \"scara\" (link1_mm, link2_mm)",
    );
    let m = config::parse(
        &edited(&[(
            "kinematics = \"identity\"",
            "kinematics = \"scara\"\nscara = { link1_mm = 200.0, link2_mm = 150.0 }",
        )]),
        "t",
    )
    .unwrap();
    assert_eq!(
        m.machine.kinematics(),
        config::Kinematics::Scara {
            link1_mm: 200.0,
            link2_mm: 150.0
        }
    );
}

#[test]
fn all_validation_errors_are_reported_at_once() {
    let found = issues(&[
        ("priority = 80", "priority = 0"),
        ("max_acceleration = 1000.0", "max_acceleration = -1.0"),
        ("drive = \"z\"", "drive = \"nowhere\""),
        ("max_rpm = 24000.0", "max_rpm = -1.0"),
        ("estop_input = \"estop\"", "estop_input = \"missing\""),
    ]);
    let keys: Vec<&str> = found.iter().map(|i| i.split(':').next().unwrap()).collect();
    for key in [
        "thread[0] (servo).priority",
        "axis[0] (X).max_acceleration",
        "axis[2] (Z).drive",
        "spindle.max_rpm",
        "safety.estop_input",
    ] {
        assert!(keys.contains(&key), "{key} missing from {keys:?}");
    }
    let err = config::parse(
        &edited(&[
            ("priority = 80", "priority = 0"),
            ("max_rpm = 24000.0", "max_rpm = -1.0"),
        ]),
        "m.toml",
    )
    .unwrap_err();
    let text = err.to_string();
    assert!(
        text.starts_with("m.toml: 2 error(s):\n  thread[0]"),
        "{text}"
    );
}

#[test]
fn a_missing_file_is_an_io_error_naming_the_path() {
    let err = config::load(std::path::Path::new("/nonexistent/machine.toml")).unwrap_err();
    assert!(matches!(err, ConfigError::Io { .. }));
    assert!(
        err.to_string().contains("/nonexistent/machine.toml"),
        "{err}"
    );
}

/// Every table of the file, including inline ones, rejects a key it does not know and names
/// it with its full path.
#[test]
fn every_section_rejects_unknown_keys() {
    let cases: &[(&str, &str, &str)] = &[
        ("[machine]\n", "[machine]\nzzz = 1\n", "machine.zzz"),
        (
            "[[thread]]\nname = \"servo\"",
            "[[thread]]\nzzz = 1\nname = \"servo\"",
            "thread[0].zzz",
        ),
        (
            "[[axis]]\nname = \"X\"",
            "[[axis]]\nzzz = 1\nname = \"X\"",
            "axis[0].zzz",
        ),
        (
            "sequence = 0 }",
            "sequence = 0, zzz = 1 }",
            "axis[2].home.zzz",
        ),
        (
            "[[drive]]\nname = \"x\"",
            "[[drive]]\nzzz = 1\nname = \"x\"",
            "drive[0].zzz",
        ),
        (
            "[drive.sim]\n",
            "[drive.sim]\nzzz = 1\n",
            "drive[0].sim.zzz",
        ),
        (
            "{ min = 0.5, max = 5.0 }",
            "{ min = 0.5, max = 5.0, zzz = 1 }",
            "drive[2].sim.home_switch.zzz",
        ),
        ("[[io]]\n", "[[io]]\nzzz = 1\n", "io[0].zzz"),
        (
            "{ name = \"probe\" }",
            "{ name = \"probe\", zzz = 1 }",
            "io[0].digital_inputs[1].zzz",
        ),
        (
            "{ name = \"spindle_speed\" }",
            "{ name = \"spindle_speed\", zzz = 1 }",
            "io[0].analog_outputs[0].zzz",
        ),
        ("[spindle]\n", "[spindle]\nzzz = 1\n", "spindle.zzz"),
        ("[coolant]\n", "[coolant]\nzzz = 1\n", "coolant.zzz"),
        ("[control]\n", "[control]\nzzz = 1\n", "control.zzz"),
        ("[logging]\n", "[logging]\nzzz = 1\n", "logging.zzz"),
        ("[motion]\n", "[motion]\nzzz = 1\n", "motion.zzz"),
        ("[safety]\n", "[safety]\nzzz = 1\n", "safety.zzz"),
        (
            "[machine]\n",
            "[tool_table]\npath = \"t.tbl\"\nzzz = 1\n[machine]\n",
            "tool_table.zzz",
        ),
        (
            "kinematics = \"identity\"",
            "kinematics = \"scara\"\nscara = { link1_mm = 1.0, link2_mm = 1.0, zzz = 1 }",
            "machine.scara.zzz",
        ),
    ];
    for (from, to, key) in cases {
        let (found, msg) = parse_error(&[(from, to)]);
        assert_eq!(&found, key, "{msg}");
        assert!(msg.contains("unknown field `zzz`"), "{key}: {msg}");
    }
}

#[test]
fn a_missing_section_is_named() {
    let start = BUILTIN_SIM_TOML.find("[safety]").unwrap();
    let text = &BUILTIN_SIM_TOML[..start];
    match config::parse(text, "t") {
        Err(ConfigError::Parse { key, message, .. }) => {
            assert_eq!(key, "(root)");
            assert!(message.contains("missing field `safety`"), "{message}");
        }
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn the_simulated_touch_plate_is_checked() {
    let found = issues(&[(
        "touch_plate = { input = \"probe\", axis = \"Z\", top = -80.0 }",
        "touch_plate = { input = \"prob\", axis = \"A\", top = -80.0 }",
    )]);
    assert_has(
        &found,
        "io[0] (panel).touch_plate.input: \"prob\" is not a digital input of this device",
    );
    assert_has(
        &found,
        "io[0] (panel).touch_plate.axis: no [[axis]] named A",
    );
}
