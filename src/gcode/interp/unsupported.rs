//! G codes LinuxCNC has and hytask does not implement. Each is refused with its name, so a
//! program that uses one fails on the line of the code and says which feature is missing,
//! instead of tripping over one of its words ("I word with no G2, G3…").

/// The message for an unsupported G code (tenths), or None if hytask implements it.
pub(crate) fn g_code(g: u16) -> Option<&'static str> {
    Some(match g {
        410 | 420 => {
            "G41/G42 (cutter radius compensation) is not supported by hytask; use a CAM-compensated path"
        }
        411 | 421 => {
            "G41.1/G42.1 (dynamic cutter radius compensation) is not supported by hytask; use a CAM-compensated path"
        }
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
        assert!(g_code(420).is_some_and(|m| m.contains("cutter radius compensation")));
        for implemented in [
            0, 10, 20, 30, 50, 51, 70, 80, 330, 331, 382, 760, 400, 430, 431, 490, 800, 810, 890,
        ] {
            assert_eq!(g_code(implemented), None, "G{}", implemented / 10);
        }
    }
}
