//! LinuxCNC's parameter file (`PARAMETER_FILE` in the ini, `rs274 -v FILE`): the numbered
//! parameters that outlive a program, one `number<TAB>value` line each, ascending.
//!
//! Why a file: work offsets (G10 L2/L20, G54…G59.3 and the active one, #5220), the G92
//! offset and its enable flag (#5210–#5219) and the G28/G30 positions are machine state an
//! operator sets once; LinuxCNC keeps them across restarts in this file, and programs
//! written for it expect them to be there. hytask reads and writes the same format, so a
//! LinuxCNC var file can be used as it is and `rs274 -v` can check hytask's results.
//!
//! Saving follows rs274: every parameter of [`REQUIRED`] plus every other one the loaded
//! file listed (so a user parameter such as `#100` becomes persistent by adding a line for
//! it), in ascending order, values printed with six decimals. The file is replaced
//! atomically (a temporary file in the same directory, then a rename), so a crash while
//! saving leaves the old file or the new one, never half of one.

use super::params::NUM_PARAMS;
use super::GcodeError;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Ranges of the parameters rs274 always saves: G28 and G30 positions, the G92 flag and
/// offsets, the active coordinate system and the nine coordinate systems (X…W and R).
pub const REQUIRED: &[(u16, u16)] = &[
    (5161, 5169),
    (5181, 5189),
    (5210, 5220),
    (5221, 5230),
    (5241, 5250),
    (5261, 5270),
    (5281, 5290),
    (5301, 5310),
    (5321, 5330),
    (5341, 5350),
    (5361, 5370),
    (5381, 5390),
];

/// First parameter that a var file cannot set at start: the tool, its offsets and the
/// current position (#5400…) are the machine's state, which rs274 re-reads after loading
/// the file. Such lines are still saved back (with the current value), as rs274 does.
pub const FIRST_LIVE: u16 = 5400;

/// Persistent parameter values, ascending by number, each number once.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VarFile {
    /// `(number, value)`, ascending.
    pub values: Vec<(u16, f64)>,
}

impl VarFile {
    /// Parses var-file text; `name` names the file in errors. Blank lines are skipped; every
    /// other line must be `number value` (whitespace-separated), numbers ascending and in
    /// 1..=5601. rs274 skips a line it cannot read; hytask refuses it (file:line) so that a
    /// damaged file never silently loses an offset.
    pub fn parse(name: &str, text: &str) -> Result<VarFile, GcodeError> {
        let mut values: Vec<(u16, f64)> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let err = |col: usize, message: String| GcodeError {
                file: name.to_string(),
                line: u32::try_from(i + 1).unwrap_or(u32::MAX),
                col: u32::try_from(col + 1).unwrap_or(u32::MAX),
                message,
            };
            let t = line.trim();
            if t.is_empty() {
                continue;
            }
            let mut f = t.split_whitespace();
            let (Some(n), Some(v), None) = (f.next(), f.next(), f.next()) else {
                return Err(err(
                    0,
                    format!("Parameter file line is not 'number<TAB>value': {t:?}"),
                ));
            };
            let num: u16 = n
                .parse()
                .ok()
                .filter(|&k| k >= 1 && usize::from(k) < NUM_PARAMS)
                .ok_or_else(|| {
                    err(
                        0,
                        format!(
                            "Parameter number out of range: {n} (1..={})",
                            NUM_PARAMS - 1
                        ),
                    )
                })?;
            let val: f64 = v
                .parse()
                .ok()
                .filter(|x: &f64| x.is_finite())
                .ok_or_else(|| err(line.find(v).unwrap_or(0), format!("Bad value: {v:?}")))?;
            if num == 5220 && !(val.fract() == 0.0 && (1.0..=9.0).contains(&val)) {
                return Err(err(
                    line.find(v).unwrap_or(0),
                    format!("#5220 (active coordinate system) must be 1 to 9, not {v}"),
                ));
            }
            if values.last().is_some_and(|&(p, _)| p >= num) {
                return Err(err(
                    0,
                    format!(
                        "Parameter file out of order: #{num} after #{}",
                        values[values.len() - 1].0
                    ),
                ));
            }
            values.push((num, val));
        }
        Ok(VarFile { values })
    }

    /// Reads a var file. A missing file is an empty one (a new machine; the file is created
    /// at the first save), as rs274 does.
    pub fn load(path: &Path) -> Result<VarFile, GcodeError> {
        match std::fs::read_to_string(path) {
            Ok(t) => Self::parse(&path.display().to_string(), &t),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(VarFile::default()),
            Err(e) => Err(GcodeError {
                file: path.display().to_string(),
                line: 1,
                col: 1,
                message: format!("Unable to open parameter file: {e}"),
            }),
        }
    }

    /// The numbers saved: [`REQUIRED`] and every number of `self`, ascending.
    pub fn saved_numbers(&self) -> Vec<u16> {
        let mut n: Vec<u16> = REQUIRED.iter().flat_map(|&(a, b)| a..=b).collect();
        n.extend(self.values.iter().map(|v| v.0));
        n.sort_unstable();
        n.dedup();
        n
    }

    /// The file text, as rs274 writes it (`%d\t%f`).
    pub fn to_text(&self) -> String {
        let mut s = String::with_capacity(self.values.len() * 16);
        for (n, v) in &self.values {
            s.push_str(&format!("{n}\t{v:.6}\n"));
        }
        s
    }

    /// Replaces the file at `path` atomically (temporary file beside it, flushed, renamed).
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
        let file = path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_else(|| "var".into());
        let tmp = dir
            .unwrap_or_else(|| Path::new("."))
            .join(format!(".{file}.tmp{}", std::process::id()));
        let write = || -> std::io::Result<()> {
            let mut f = std::fs::File::create(&tmp)?;
            f.write_all(self.to_text().as_bytes())?;
            f.sync_all()
        };
        if let Err(e) = write() {
            let _ = std::fs::remove_file(&tmp);
            return Err(e);
        }
        std::fs::rename(&tmp, path)
    }
}

/// A machine's var file while the daemon runs: the values the next job starts from, and the
/// file they are saved to. Jobs read a snapshot when they are prepared; a job that has run
/// to its end commits the values it left ([`ParamStore::commit`]), which also saves the file.
/// Never touched by the realtime threads.
#[derive(Debug)]
pub struct ParamStore {
    path: PathBuf,
    current: Mutex<Arc<VarFile>>,
}

impl ParamStore {
    /// Loads `path` (missing: empty); errors name file and line.
    pub fn load(path: &Path) -> Result<ParamStore, GcodeError> {
        Ok(ParamStore {
            path: path.to_path_buf(),
            current: Mutex::new(Arc::new(VarFile::load(path)?)),
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The values a job prepared now starts from.
    pub fn snapshot(&self) -> Arc<VarFile> {
        self.current
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Makes `values` current and saves them.
    pub fn commit(&self, values: VarFile) -> std::io::Result<()> {
        let v = Arc::new(values);
        *self.current.lock().unwrap_or_else(|p| p.into_inner()) = v.clone();
        v.save(&self.path)
    }

    /// Saves the current values (at daemon stop).
    pub fn save(&self) -> std::io::Result<()> {
        self.snapshot().save(&self.path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_tab_and_space_separated_lines_and_blank_lines() {
        let v = VarFile::parse("t.var", "5210\t1\n\n5221  2.5\n").unwrap();
        assert_eq!(v.values, vec![(5210, 1.0), (5221, 2.5)]);
    }

    #[test]
    fn errors_name_file_and_line() {
        let e = VarFile::parse("m.var", "5220\t1\n5210\t1\n").unwrap_err();
        assert_eq!((e.file.as_str(), e.line), ("m.var", 2));
        assert!(e.message.contains("out of order"), "{e}");
        let e = VarFile::parse("m.var", "5220\n").unwrap_err();
        assert_eq!(e.line, 1);
        let e = VarFile::parse("m.var", "1\t0\n6000\t1\n").unwrap_err();
        assert!(e.to_string().starts_with("m.var:2:"), "{e}");
        assert!(e.message.contains("6000"), "{e}");
        let e = VarFile::parse("m.var", "100\tabc\n").unwrap_err();
        assert!(e.message.contains("abc"), "{e}");
    }

    #[test]
    fn saves_required_numbers_and_the_loaded_ones() {
        let v = VarFile::parse("t", "100\t3\n5400\t7\n").unwrap();
        let n = v.saved_numbers();
        assert_eq!(n.first(), Some(&100));
        assert_eq!(n.last(), Some(&5400));
        assert!(n.contains(&5220) && n.contains(&5390) && !n.contains(&5231));
        assert_eq!(n.len(), 2 + 9 + 9 + 11 + 90);
    }

    #[test]
    fn save_replaces_the_file_atomically_and_round_trips() {
        let dir = std::env::temp_dir().join(format!("hytask-var-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("m.var");
        std::fs::write(&p, "garbage").unwrap();
        let v = VarFile {
            values: vec![(5220, 2.0), (5221, -0.0), (5241, 1.25)],
        };
        v.save(&p).unwrap();
        assert_eq!(
            std::fs::read_to_string(&p).unwrap(),
            "5220\t2.000000\n5221\t-0.000000\n5241\t1.250000\n"
        );
        assert_eq!(VarFile::load(&p).unwrap().values[2], (5241, 1.25));
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            1,
            "no temp file left"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_store_commits_and_saves() {
        let dir = std::env::temp_dir().join(format!("hytask-store-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("s.var");
        std::fs::write(&p, "5220\t2\n").unwrap();
        let s = ParamStore::load(&p).unwrap();
        assert_eq!(s.snapshot().values, vec![(5220, 2.0)]);
        s.commit(VarFile {
            values: vec![(5220, 3.0)],
        })
        .unwrap();
        assert_eq!(s.snapshot().values, vec![(5220, 3.0)]);
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "5220\t3.000000\n");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_missing_file_is_empty() {
        let v = VarFile::load(Path::new("/nonexistent/dir/x.var")).unwrap();
        assert!(v.values.is_empty());
    }
}
