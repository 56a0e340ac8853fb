//! RETAIN variables kept across daemon restarts (`plc.retain_file`). The scan copies the
//! retained cells into shared atomics under a sequence counter (no allocation, no lock); a
//! writer thread off the realtime path takes consistent copies once a second and, when they
//! changed, writes the file atomically (a temporary file, then rename). At start the file's
//! values are restored before the first scan. Lines are `NAME=VALUE` (IEC literals).

use super::value::format_cell;
use super::{Program, Ty, VarId};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// The retained cells as the scan last left them.
#[derive(Debug)]
pub struct RetainShared {
    seq: AtomicU64,
    cells: Vec<AtomicU64>,
    /// Replaced by a new program version's: its writer stops without a last write, so the
    /// old version's values never overwrite the new one's.
    retired: std::sync::atomic::AtomicBool,
}

impl RetainShared {
    /// Stops this writer for good (a new program version took over the file).
    pub fn retire(&self) {
        self.retired.store(true, Ordering::Release);
    }

    /// Publishes `program`'s retained cells (realtime: stores only).
    pub fn publish(&self, program: &Program, ids: &[VarId]) {
        self.seq.fetch_add(1, Ordering::AcqRel);
        for (c, id) in self.cells.iter().zip(ids) {
            c.store(program.cell(*id), Ordering::Relaxed);
        }
        self.seq.fetch_add(1, Ordering::AcqRel);
    }

    /// A consistent copy (retries while the scan is writing).
    fn snapshot(&self) -> Vec<u64> {
        loop {
            let s0 = self.seq.load(Ordering::Acquire);
            let v: Vec<u64> = self
                .cells
                .iter()
                .map(|c| c.load(Ordering::Relaxed))
                .collect();
            if s0.is_multiple_of(2) && self.seq.load(Ordering::Acquire) == s0 {
                return v;
            }
            std::thread::yield_now();
        }
    }
}

/// The retained variables of a program and where they are kept.
pub struct Retain {
    /// Their ids, in table order.
    pub ids: Vec<VarId>,
    /// Shared with the writer.
    pub shared: Arc<RetainShared>,
}

/// Restoring the file failed.
#[derive(Debug, thiserror::Error)]
#[error("plc.retain_file {path}:{line}: {what}")]
pub struct RetainError {
    path: String,
    line: usize,
    what: String,
}

/// Restores `path` into `program` (a missing file is a first start) and starts the writer.
/// Variables no longer in the program, or no longer RETAIN, are skipped.
pub fn start(program: &mut Program, path: &Path) -> Result<Retain, RetainError> {
    let ids: Vec<VarId> = (0..program.vars().len() as u32)
        .map(VarId)
        .filter(|id| program.info(*id).retain)
        .collect();
    if let Ok(text) = std::fs::read_to_string(path) {
        for (n, line) in text.lines().enumerate() {
            let err = |what: String| RetainError {
                path: path.display().to_string(),
                line: n + 1,
                what,
            };
            let Some((name, value)) = line.split_once('=') else {
                continue;
            };
            let Some(id) = program.var(name.trim()).filter(|id| ids.contains(id)) else {
                continue;
            };
            let v = program
                .parse(id, value.trim())
                .ok_or_else(|| err(format!("{value:?} is not a value of {name}")))?;
            program.set(id, v).map_err(|e| err(e.to_string()))?;
        }
    }
    Ok(follow(program, path))
}

/// Starts a writer of `program`'s RETAIN variables to `path` without restoring from it (a
/// new program version that took its values over from the running one).
pub fn follow(program: &Program, path: &Path) -> Retain {
    let ids: Vec<VarId> = (0..program.vars().len() as u32)
        .map(VarId)
        .filter(|id| program.info(*id).retain)
        .collect();
    let shared = Arc::new(RetainShared {
        seq: AtomicU64::new(0),
        cells: ids
            .iter()
            .map(|id| AtomicU64::new(program.cell(*id)))
            .collect(),
        retired: std::sync::atomic::AtomicBool::new(false),
    });
    let names: Vec<(String, Ty)> = ids
        .iter()
        .map(|id| (program.info(*id).name.clone(), program.info(*id).ty))
        .collect();
    let writer = shared.clone();
    let path = path.to_path_buf();
    if !ids.is_empty() {
        let _ = std::thread::Builder::new()
            .name("plc-retain".into())
            .spawn(move || write_loop(&writer, &names, &path));
    }
    Retain { ids, shared }
}

fn write_loop(shared: &Arc<RetainShared>, names: &[(String, Ty)], path: &Path) {
    let mut last = shared.snapshot();
    loop {
        std::thread::sleep(Duration::from_millis(1000));
        if shared.retired.load(Ordering::Acquire) {
            return;
        }
        // The task is gone (machine shut down): one last write, then stop.
        let done = Arc::strong_count(shared) == 1;
        let now = shared.snapshot();
        if now != last || done {
            if let Err(e) = write_file(path, names, &now) {
                tracing::warn!("plc.retain_file {}: {e}", path.display());
            }
            last = now;
        }
        if done {
            return;
        }
    }
}

/// Writes the file atomically: a temporary file beside it, then rename.
fn write_file(path: &Path, names: &[(String, Ty)], cells: &[u64]) -> std::io::Result<()> {
    let mut text = String::new();
    for ((name, ty), c) in names.iter().zip(cells) {
        text.push_str(&format!("{name}={}\n", format_cell(*ty, *c, |_, _| None)));
    }
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)
}
