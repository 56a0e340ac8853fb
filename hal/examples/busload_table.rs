//! Prints the CANopen bus-load table (1-8 drives at 250 Hz-2 kHz on 1 Mbit/s and
//! 500 kbit/s) for the default CSP layout, with and without the velocity TPDO, computed by
//! the same code that enforces the budget at configuration time.
//!
//! `cargo run -p hytask-hal --example busload_table`

use hytask_hal::canopen::busload::{CycleTraffic, DEFAULT_LIMIT};

fn main() {
    for (title, with_velocity) in [
        (
            "RPDO1 (6 B) + TPDO1 (6 B) per drive, SYNC without counter",
            false,
        ),
        (
            "RPDO1 (6 B) + TPDO1 (6 B) + TPDO2 velocity (5 B) per drive",
            true,
        ),
    ] {
        println!("{title}");
        let table = CycleTraffic::csp_default(with_velocity).table(
            8,
            &[250, 500, 1000, 2000],
            &[1_000_000, 500_000],
            DEFAULT_LIMIT,
        );
        println!("{table}");
    }
}
