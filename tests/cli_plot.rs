//! `hytask plot` as a user runs it: plans from the machine's home position (or `--from`),
//! writes SVG or PNG by the output's extension, refuses a bad `--from` naming it.
#![allow(clippy::unwrap_used)]

use std::process::Command;

fn hytask(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap()
}

#[test]
fn plot_writes_png_from_the_home_position_and_svg_from_a_given_start() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("plate.png");
    let out = hytask(&[
        "plot",
        "examples/jobs/demo-plate.ngc",
        "--view",
        "iso",
        "-o",
        png.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The built-in sim mill homes to X300 Y300 Z0: `hytask run` starts there.
    assert!(stdout.contains("from X300 Y300 Z0"), "{stdout}");
    let img = resvg::tiny_skia::Pixmap::decode_png(&std::fs::read(&png).unwrap()).unwrap();
    assert_eq!(img.width(), 1000);

    let svg = dir.path().join("plate.svg");
    let out = hytask(&[
        "plot",
        "examples/jobs/demo-plate.ngc",
        "--from",
        "-10,0,50",
        "--view",
        "front",
        "-o",
        svg.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("front view") && text.contains("start X-10.0 Y0.0 Z50.0"));

    let out = hytask(&[
        "plot",
        "examples/jobs/demo-plate.ngc",
        "--from",
        "1,2",
        "-o",
        "x.svg",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--from \"1,2\": give X,Y,Z"));
}
