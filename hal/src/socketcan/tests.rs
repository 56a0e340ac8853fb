//! Bus-less tests of the SocketCAN glue: names, filters, frame conversion, error-frame
//! decoding and errno classification. The socket itself is tested on a real vcan0 by
//! `tests/vcan_socketcan.rs` (run by `tests/vcan/run`).

use super::*;
use crate::error::{Error as _, ErrorKind};
use socketcan::CanErrorFrame;
use std::io;

fn vcan0() -> IfName {
    IfName::new("vcan0").unwrap()
}

#[test]
fn interface_names_are_checked() {
    assert_eq!(vcan0().to_string(), "vcan0");
    assert!(IfName::new("").is_none());
    assert!(IfName::new("a-name-of-16-chr").is_none());
    assert_eq!(
        IfName::new("exactly15chars_").unwrap().as_str(),
        "exactly15chars_"
    );
    assert!(IfName::new("can/0").is_none());
    let e = SocketCanBus::open("").unwrap_err();
    assert_eq!(e.kind(), ErrorKind::InvalidArgument);
}

#[test]
fn opening_a_missing_interface_names_it() {
    let e = SocketCanBus::open("nosuchcan7").unwrap_err();
    assert!(e.to_string().contains("nosuchcan7"), "{e}");
    // Without CAN in the kernel the socket itself cannot be made; with it, the name is
    // unknown. Either way it is not a transient condition.
    assert!(!e.kind().is_transient(), "{e}: {:?}", e.kind());
}

#[test]
fn frames_convert_both_ways() {
    let id = CanId::standard(0x601).unwrap();
    let f = CanFrame::new(id, &[0x40, 0x18, 0x10, 1, 0, 0, 0, 0]).unwrap();
    let s = to_socketcan(vcan0(), &f).unwrap();
    assert_eq!(from_socketcan(vcan0(), &s).unwrap(), f);
    let ext = CanFrame::new(CanId::extended(0x1234_5678).unwrap(), &[9]).unwrap();
    let s = to_socketcan(vcan0(), &ext).unwrap();
    assert!(EmbeddedFrame::is_extended(&s));
    assert_eq!(from_socketcan(vcan0(), &s).unwrap(), ext);
    let rtr = CanFrame::remote(CanId::standard(0x701).unwrap(), 1).unwrap();
    let s = to_socketcan(vcan0(), &rtr).unwrap();
    assert!(s.is_remote_frame());
    assert_eq!(from_socketcan(vcan0(), &s).unwrap(), rtr);
}

#[test]
fn filters_match_the_id_format_too() {
    let std_f = IdFilter::exact(CanId::standard(0x181).unwrap()).to_kernel();
    let raw: &libc::can_filter = std_f.as_ref();
    assert_eq!(raw.can_id, 0x181);
    assert_eq!(raw.can_mask, 0x7FF | libc::CAN_EFF_FLAG);
    let ext_f = IdFilter::exact(CanId::extended(0x181).unwrap()).to_kernel();
    let raw: &libc::can_filter = ext_f.as_ref();
    assert_eq!(raw.can_id, 0x181 | libc::CAN_EFF_FLAG);
    let range = IdFilter::masked(CanId::standard(0x580).unwrap(), 0x780).to_kernel();
    let raw: &libc::can_filter = range.as_ref();
    assert_eq!(
        (raw.can_id, raw.can_mask),
        (0x580, 0x780 | libc::CAN_EFF_FLAG)
    );
}

fn decode(cause: ErrorCause, state: &mut BusState) -> Option<SocketCanError> {
    let frame = CanErrorFrame::from(cause);
    decode_error(vcan0(), &frame.into_error(), state)
}

#[test]
fn bus_off_is_a_link_failure_naming_the_interface() {
    let mut st = BusState::ErrorActive;
    let e = decode(ErrorCause::BusOff, &mut st).unwrap();
    assert_eq!(e.kind(), ErrorKind::Disconnected);
    assert_eq!(e.to_string(), "CAN interface vcan0: bus off");
    assert_eq!(st, BusState::BusOff);
    assert!(decode(ErrorCause::Restarted, &mut st).is_none());
    assert_eq!(st, BusState::ErrorActive);
}

#[test]
fn error_passive_and_overflow_are_reported_warning_is_not() {
    let mut st = BusState::ErrorActive;
    assert!(decode(
        ErrorCause::Controller(ControllerProblems::TX_WARNING),
        &mut st
    )
    .is_none());
    assert_eq!(st, BusState::ErrorWarning);
    let e = decode(
        ErrorCause::Controller(ControllerProblems::RX_PASSIVE),
        &mut st,
    )
    .unwrap();
    assert!(matches!(e, SocketCanError::ErrorPassive { .. }), "{e}");
    assert!(e.to_string().contains("error-passive"), "{e}");
    assert_eq!(st, BusState::ErrorPassive);
    let e = decode(
        ErrorCause::Controller(ControllerProblems::RX_OVERFLOW),
        &mut st,
    )
    .unwrap();
    assert!(matches!(e, SocketCanError::Controller { .. }), "{e}");
    assert!(decode(ErrorCause::Controller(ControllerProblems::ACTIVE), &mut st).is_none());
    assert_eq!(st, BusState::ErrorActive);
}

#[test]
fn no_ack_is_a_timeout_and_protocol_errors_are_named() {
    let mut st = BusState::ErrorActive;
    let e = decode(ErrorCause::NoAck, &mut st).unwrap();
    assert_eq!(e.kind(), ErrorKind::Timeout);
    let e = decode(ErrorCause::BusError, &mut st).unwrap();
    assert!(
        e.to_string().starts_with("CAN interface vcan0: bus error"),
        "{e}"
    );
    assert!(decode(ErrorCause::Counters { tx: 3, rx: 0 }, &mut st).is_none());
}

#[test]
fn errno_becomes_the_named_condition() {
    let c = |errno, op| SocketCanError::from_io(vcan0(), op, io::Error::from_raw_os_error(errno));
    let e = c(libc::ENETDOWN, "send");
    assert_eq!(e.kind(), ErrorKind::Disconnected);
    assert_eq!(
        e.to_string(),
        "CAN interface vcan0 is down (`ip link set vcan0 up`)"
    );
    assert_eq!(c(libc::ENOBUFS, "send").kind(), ErrorKind::WouldBlock);
    assert_eq!(c(libc::EAGAIN, "send").kind(), ErrorKind::WouldBlock);
    assert_eq!(c(libc::ENODEV, "open").kind(), ErrorKind::InvalidArgument);
    assert_eq!(c(libc::ENODEV, "receive").kind(), ErrorKind::Disconnected);
    let e = c(libc::EPERM, "open");
    assert_eq!(e.kind(), ErrorKind::Other);
    assert!(
        e.to_string().starts_with("CAN interface vcan0: open: "),
        "{e}"
    );
}
