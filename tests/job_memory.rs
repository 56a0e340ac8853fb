//! Memory of a prepared job (issue 8): a 1,000,000-line 3-axis G1 job must prepare within
//! 300 MB of heap at its peak and keep at most 150 MB while loaded (it took 1995 MB and kept
//! 1152 MB). Measured with a counting global allocator: bytes, not wall time, so the result
//! does not depend on the host's load. `examples/job_memory.rs` prints the same figures.

use hytask::config::builtin_sim;
use hytask::machine::api::JobSource;
use hytask::machine::job;
use std::alloc::{GlobalAlloc, Layout, System};
use std::fmt::Write as _;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(by: usize) {
    let now = LIVE.fetch_add(by, Ordering::Relaxed) + by;
    PEAK.fetch_max(now, Ordering::Relaxed);
}

// SAFETY: forwards to the system allocator; only counts bytes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        // SAFETY: same contract as ours.
        let p = unsafe { System.alloc(l) };
        if !p.is_null() {
            grew(l.size());
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: same contract as ours.
        unsafe { System.dealloc(p, l) };
        LIVE.fetch_sub(l.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        // SAFETY: same contract as ours.
        let q = unsafe { System.realloc(p, l, new) };
        if !q.is_null() {
            if new >= l.size() {
                grew(new - l.size());
            } else {
                LIVE.fetch_sub(l.size() - new, Ordering::Relaxed);
            }
        }
        q
    }
}

#[global_allocator]
static A: Counting = Counting;

/// An `n`-line surfacing finish pass: zig-zag rows of 0.2 mm steps over a 2 mm Z wave, every
/// line a move of its own (the same program as `examples/job_memory.rs`).
fn surfacing(n: usize) -> String {
    let mut s = String::with_capacity(n * 30);
    s.push_str("G21 G90 G64 P0.01\nG0 X10 Y10 Z-5\nF1500\n");
    let per_row = 1000;
    for i in 0..n - 4 {
        let (row, k) = (i / per_row, i % per_row);
        let x = if row % 2 == 0 { k } else { per_row - 1 - k } as f64 * 0.2 + 10.0;
        let y = 10.0 + (row % 1000) as f64 * 0.25;
        let z = -6.0 + (x * std::f64::consts::PI).sin() * (0.5 + 0.5 * (y * 0.07).cos());
        let _ = writeln!(s, "G1 X{x:.3} Y{y:.3} Z{z:.4}");
    }
    s.push_str("M2\n");
    s
}

#[test]
fn a_million_line_job_prepares_in_300_mb_and_keeps_under_150_mb() {
    const LINES: usize = 1_000_000;
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("surface.ngc");
    std::fs::write(&path, surfacing(LINES)).expect("write the job");
    let cfg = builtin_sim().expect("built-in config");
    let (opts, motion) = (job::interp_options(&cfg), job::motion_config(&cfg));
    let src = JobSource {
        path: Some(path.display().to_string()),
        text: None,
        name: None,
    };
    let start = [10.0, 10.0, -5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let prepared = job::prepare(&src, &opts, &motion, start).expect("plans");
    let peak = PEAK.load(Ordering::Relaxed) - base;
    let kept = LIVE.load(Ordering::Relaxed) - base;
    // The job really is that big: over two million segments.
    assert!(
        prepared.plan.segment_count > 2_000_000,
        "{}",
        prepared.plan.segment_count
    );
    assert_eq!(prepared.total_lines as usize, LINES);
    assert!(
        peak <= 300 * LINES,
        "peak {} MB ({} B/line)",
        peak / 1_000_000,
        peak / LINES
    );
    assert!(
        kept <= 150 * LINES,
        "kept {} MB ({} B/line)",
        kept / 1_000_000,
        kept / LINES
    );
}
