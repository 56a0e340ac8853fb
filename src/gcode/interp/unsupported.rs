//! G codes LinuxCNC has and hytask does not implement. Each is refused with its name, so a
//! program that uses one fails on the line of the code and says which feature is missing,
//! instead of tripping over one of its words ("I word with no G2, G3…").

/// The message for an unsupported G code (tenths), or None if hytask implements it.
pub(crate) fn g_code(g: u16) -> Option<&'static str> {
    Some(match g {
        870 => "G87 (back boring cycle) is not supported by hytask",
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unsupported_codes_name_themselves() {
        assert!(g_code(870).is_some_and(|m| m.starts_with("G87 ")));
        for implemented in [
            0, 10, 20, 30, 50, 51, 70, 80, 330, 331, 382, 400, 410, 411, 420, 421, 430, 431, 490,
            700, 710, 711, 712, 720, 721, 722, 760, 800, 810, 890,
        ] {
            assert_eq!(g_code(implemented), None, "G{}", implemented / 10);
        }
    }
}
