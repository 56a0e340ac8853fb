//! Configuration errors. Every problem names the section and key it is about, so that a
//! person can fix the file without guessing; validation collects all problems at once.

use std::fmt;
use std::path::PathBuf;

/// One problem with the configuration, tied to its key (e.g.
/// `axis[1] (Y).max_velocity: must be > 0, got -5`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Issue {
    /// The section and key: `axis[1] (Y).max_velocity`, `safety.estop_input`.
    pub key: String,
    /// What is wrong, with the offending value where it helps.
    pub message: String,
}

impl fmt::Display for Issue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.key, self.message)
    }
}

/// Why a configuration could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// The file is not valid TOML, or a key is unknown, missing or of the wrong type.
    /// Deserialisation stops at the first such problem.
    #[error("{origin}: {key}: {message}")]
    Parse {
        /// Where the text came from (a path, or "built-in sim").
        origin: String,
        /// The section and key (`axis[1].max_velocity`); `(root)` for the top level.
        key: String,
        /// The parser's message, with line and column.
        message: String,
    },
    /// The file parsed but its values are inconsistent: every problem found is listed.
    #[error("{origin}: {} error(s):\n{}", .issues.len(), IssueList(.issues))]
    Invalid {
        /// Where the text came from.
        origin: String,
        /// All problems, in file order.
        issues: Vec<Issue>,
    },
    /// The configuration is valid but names backends that this build cannot run. Reported
    /// when a machine is deployed, not when a file is checked, so that a configuration for
    /// real hardware can be validated anywhere.
    #[error("backends not available in this build:\n{}", IssueList(.0))]
    Unavailable(Vec<Issue>),
}

impl ConfigError {
    /// The individual problems: one for a parse error, all of them for validation.
    pub fn issues(&self) -> Vec<Issue> {
        match self {
            ConfigError::Io { path, source } => vec![Issue {
                key: path.display().to_string(),
                message: source.to_string(),
            }],
            ConfigError::Parse { key, message, .. } => vec![Issue {
                key: key.clone(),
                message: message.clone(),
            }],
            ConfigError::Invalid { issues, .. } | ConfigError::Unavailable(issues) => {
                issues.clone()
            }
        }
    }
}

struct IssueList<'a>(&'a [Issue]);

impl fmt::Display for IssueList<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, issue) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "  {issue}")?;
        }
        Ok(())
    }
}

/// Collects validation problems. Checks never stop at the first problem: each section adds
/// what it finds and the caller reports them all.
#[derive(Debug, Default)]
pub struct Issues(Vec<Issue>);

impl Issues {
    /// Records a problem with `key`.
    pub fn push(&mut self, key: impl Into<String>, message: impl Into<String>) {
        self.0.push(Issue {
            key: key.into(),
            message: message.into(),
        });
    }

    /// Checks `value > 0` (and finite).
    pub fn positive(&mut self, key: impl fmt::Display, value: f64) {
        if !(value.is_finite() && value > 0.0) {
            self.push(key.to_string(), format!("must be > 0, got {value}"));
        }
    }

    /// Checks `value >= 0` (and finite).
    pub fn non_negative(&mut self, key: impl fmt::Display, value: f64) {
        if !(value.is_finite() && value >= 0.0) {
            self.push(key.to_string(), format!("must be >= 0, got {value}"));
        }
    }

    /// Checks that `value` is finite.
    pub fn finite(&mut self, key: impl fmt::Display, value: f64) {
        if !value.is_finite() {
            self.push(
                key.to_string(),
                format!("must be a finite number, got {value}"),
            );
        }
    }

    /// Checks `min <= value <= max`.
    pub fn in_range<T: PartialOrd + fmt::Display>(
        &mut self,
        key: impl fmt::Display,
        value: T,
        min: T,
        max: T,
    ) {
        if !(value >= min && value <= max) {
            self.push(
                key.to_string(),
                format!("must be in {min}..={max}, got {value}"),
            );
        }
    }

    /// Checks that a name is non-empty and made of letters, digits, `_` and `-`, so that it
    /// can be used on the control socket and in G-code comments without quoting.
    pub fn name(&mut self, key: impl fmt::Display, value: &str) {
        if value.is_empty() {
            self.push(key.to_string(), "must not be empty");
        } else if !value
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            self.push(
                key.to_string(),
                format!("{value:?}: use only letters, digits, '_' and '-'"),
            );
        }
    }

    /// True when nothing was recorded.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The recorded problems.
    pub fn into_vec(self) -> Vec<Issue> {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checks_name_key_and_value() {
        let mut issues = Issues::default();
        issues.positive("axis[1] (Y).max_velocity", -5.0);
        issues.non_negative("a.b", -1.0);
        issues.in_range("thread[0] (servo).priority", 0, 1, 99);
        issues.finite("c", f64::NAN);
        issues.name("io[0].name", "a b");
        issues.name("io[1].name", "");
        issues.positive("ok", 1.0);
        issues.in_range("ok", 5, 1, 99);
        let v: Vec<String> = issues.into_vec().iter().map(ToString::to_string).collect();
        assert_eq!(
            v,
            [
                "axis[1] (Y).max_velocity: must be > 0, got -5",
                "a.b: must be >= 0, got -1",
                "thread[0] (servo).priority: must be in 1..=99, got 0",
                "c: must be a finite number, got NaN",
                "io[0].name: \"a b\": use only letters, digits, '_' and '-'",
                "io[1].name: must not be empty",
            ]
        );
    }

    #[test]
    fn invalid_error_lists_every_issue() {
        let e = ConfigError::Invalid {
            origin: "m.toml".into(),
            issues: vec![
                Issue {
                    key: "a".into(),
                    message: "x".into(),
                },
                Issue {
                    key: "b".into(),
                    message: "y".into(),
                },
            ],
        };
        assert_eq!(e.to_string(), "m.toml: 2 error(s):\n  a: x\n  b: y");
        assert_eq!(e.issues().len(), 2);
    }
}
