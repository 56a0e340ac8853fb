//! G-code front-end throughput (MB/s of program text): lexing+parsing alone, the whole
//! interpreter (`load_str`), and the rs274-format trace printer. The program is generated
//! in memory in the style of CAM output (short G1 moves, arcs, canned drilling).

// criterion_group! generates an undocumented function.
#![allow(missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use hytask::gcode::{canon_fmt, load_str, parser, InterpOptions};
use std::fmt::Write as _;

fn program(lines: usize) -> String {
    let mut s = String::from("G21 G90 G94 G17 G64 P0.01\nF1500 S10000 M3\nG0 X0 Y0 Z5\nG1 Z-1\n");
    let mut i = 0usize;
    let (mut x, mut y) = (0.0f64, 50.0f64);
    while i < lines {
        let t = i as f64;
        if i.is_multiple_of(5000) {
            s.push_str("G98 G81 X10 Y10 Z-3 R1 F200\nX20\nX30\nG80\nG1 Z-1 F1500\n");
            i += 5;
            continue;
        }
        if i % 50 == 49 {
            x += 4.0;
            let _ = writeln!(s, "G2 X{x:.4} Y{y:.4} I2 J0");
        } else {
            x = (50.0 * (t * 0.001).sin() * 1e4).round() / 1e4;
            y = (50.0 * (t * 0.0013).cos() * 1e4).round() / 1e4;
            let _ = writeln!(
                s,
                "G1 X{x:.4} Y{y:.4} Z{:.4}",
                -1.0 - 0.5 * (t * 0.01).sin()
            );
        }
        i += 1;
    }
    s.push_str("G0 Z5\nM5\nM2\n");
    s
}

fn bench(c: &mut Criterion) {
    let text = program(20_000);
    let opts = InterpOptions::default();
    let prog = load_str("bench.ngc", &text, &opts).expect("bench program is valid");
    let mut g = c.benchmark_group("gcode");
    g.throughput(Throughput::Bytes(text.len() as u64));
    g.sample_size(20);
    g.bench_function("parse_lines", |b| {
        let mut line = parser::Line::default();
        b.iter(|| {
            for l in text.lines() {
                let _ = parser::parse_line_into(l, 64, &mut line);
            }
        })
    });
    g.bench_function("interpret", |b| {
        b.iter(|| load_str("bench.ngc", &text, &opts).map(|p| p.canon.len()))
    });
    g.bench_function("format_trace", |b| {
        let mut out = Vec::with_capacity(text.len() * 2);
        b.iter(|| {
            out.clear();
            canon_fmt::write_trace(&mut out, &prog.canon);
            out.len()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
