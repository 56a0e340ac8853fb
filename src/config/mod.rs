//! The machine description: one TOML file, `deny_unknown_fields`, validated with errors that
//! name section and key.
