//! Memory of a prepared job: peak and kept heap bytes of `job::prepare` for a generated
//! N-line 3-axis G1 surfacing program, side by side with the file size, and the cost per line.
//!
//! ```text
//! cargo run --release --example job_memory -- 1000000
//! ```
//!
//! A counting global allocator measures the heap (deterministic, unlike RSS): "peak" is the
//! most bytes live at once during preparation above what was live before, "kept" what the
//! prepared job still holds. VmHWM (the process' resident high-water mark) is printed too,
//! as a cross-check that includes the allocator's own overhead.

use hytask::config::builtin_sim;
use hytask::machine::api::JobSource;
use hytask::machine::job;
use std::alloc::{GlobalAlloc, Layout, System};
use std::io::Write;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator; only counts bytes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.alloc(l) };
        if !p.is_null() {
            let now = LIVE.fetch_add(l.size(), Ordering::Relaxed) + l.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(p, l) };
        LIVE.fetch_sub(l.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let q = unsafe { System.realloc(p, l, new) };
        if !q.is_null() {
            if new >= l.size() {
                let now = LIVE.fetch_add(new - l.size(), Ordering::Relaxed) + new - l.size();
                PEAK.fetch_max(now, Ordering::Relaxed);
            } else {
                LIVE.fetch_sub(l.size() - new, Ordering::Relaxed);
            }
        }
        q
    }
}

#[global_allocator]
static A: Counting = Counting;

/// Writes an `n`-line 3-axis surfacing program: zig-zag rows of 0.2 mm G1 steps in X over a
/// surface with a 2 mm wave in Z, stepping over in Y at each row end: a CAM finishing pass
/// whose every line is a move of its own (nothing merges within G64 P0.01).
fn surfacing(n: usize, out: &mut impl Write) -> std::io::Result<()> {
    writeln!(out, "G21 G90 G64 P0.01")?;
    writeln!(out, "G0 X10 Y10 Z-5")?;
    writeln!(out, "F1500")?;
    let per_row = 1000;
    for i in 0..n.saturating_sub(4) {
        let row = i / per_row;
        let k = i % per_row;
        let x = if row % 2 == 0 { k } else { per_row - 1 - k } as f64 * 0.2 + 10.0;
        let y = 10.0 + (row % 1000) as f64 * 0.25;
        let z = -6.0 + (x * std::f64::consts::PI).sin() * (0.5 + 0.5 * (y * 0.07).cos());
        writeln!(out, "G1 X{x:.3} Y{y:.3} Z{z:.4}")?;
    }
    writeln!(out, "M2")
}

fn vm_hwm_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let l = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    l.split_whitespace().nth(1)?.parse().ok()
}

fn main() -> anyhow::Result<()> {
    let n: usize = match std::env::args().nth(1) {
        Some(a) => a.parse()?,
        None => 1_000_000,
    };
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("surface.ngc");
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&path)?);
        surfacing(n, &mut f)?;
        f.flush()?;
    }
    let file_bytes = std::fs::metadata(&path)?.len();
    let cfg = builtin_sim()?;
    let src = JobSource {
        path: Some(path.display().to_string()),
        text: None,
        name: None,
    };
    let start = [10.0, 10.0, -5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let t = std::time::Instant::now();
    let prepared = job::prepare(
        &src,
        &job::interp_options(&cfg),
        &job::motion_config(&cfg),
        start,
    )?;
    let secs = t.elapsed().as_secs_f64();
    let peak = PEAK.load(Ordering::Relaxed) - base;
    let kept = LIVE.load(Ordering::Relaxed) - base;
    let mb = |b: usize| b as f64 / 1e6;
    println!("lines           {n}");
    println!("file            {:.1} MB", file_bytes as f64 / 1e6);
    println!(
        "peak            {:.1} MB  ({:.0} B/line)",
        mb(peak),
        peak as f64 / n as f64
    );
    println!(
        "kept            {:.1} MB  ({:.0} B/line)",
        mb(kept),
        kept as f64 / n as f64
    );
    println!("segments        {}", prepared.plan.segment_count);
    println!("planned time    {:.0} s", prepared.plan.duration_s);
    println!("prepare         {secs:.1} s");
    // While it runs: the feeder plans the job again (see `machine::job`); what that costs
    // on top of what the loaded job keeps.
    if let Some(replay) = &prepared.replay {
        let before = LIVE.load(Ordering::Relaxed);
        PEAK.store(before, Ordering::Relaxed);
        let mut items = 0u64;
        let t = std::time::Instant::now();
        let done = replay.run_ahead(&mut |batch| {
            items += batch.len() as u64;
            true
        });
        let secs = t.elapsed().as_secs_f64();
        anyhow::ensure!(done == Ok(true), "replay: {done:?}");
        anyhow::ensure!(items == prepared.item_count(), "replay gave {items} items");
        let run_peak = PEAK.load(Ordering::Relaxed) - before;
        println!(
            "running: feeder  {:.1} MB peak on top ({:.0} B/line), {secs:.1} s to plan again",
            mb(run_peak),
            run_peak as f64 / n as f64
        );
    }
    if let Some(k) = vm_hwm_kib() {
        println!("VmHWM           {:.1} MB", k as f64 / 1e3);
    }
    drop(prepared);
    Ok(())
}
