use super::*;
use crate::canopen::CanOpenError;
use crate::error::{Error, ErrorKind};
use std::collections::BTreeMap;
use std::time::Duration;

struct Od(BTreeMap<(u16, u8), Vec<u8>>);

impl ObjectAccess for Od {
    fn read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, SdoAbortCode> {
        self.0
            .get(&(index, sub))
            .cloned()
            .ok_or(SdoAbortCode::ObjectDoesNotExist)
    }
    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), SdoAbortCode> {
        if index == 0x1000 {
            return Err(SdoAbortCode::ReadOnly);
        }
        self.0.insert((index, sub), data.to_vec());
        Ok(())
    }
}

fn node() -> NodeId {
    NodeId::new(5).unwrap()
}

fn od() -> Od {
    let mut m = BTreeMap::new();
    m.insert((0x1000, 0), vec![0x92, 0x01, 0x02, 0x00]);
    m.insert((0x1008, 0), b"hytask loopback drive".to_vec());
    Od(m)
}

/// Runs a transfer to its end between a client and a server; returns the final step and
/// the number of frames the client sent.
fn run(
    client: &mut SdoClient,
    server: &mut SdoServer,
    od: &mut Od,
    first: CanFrame,
) -> (SdoStep, usize) {
    let mut to_server = first;
    let t = Duration::ZERO;
    for sent in 1..1000 {
        let Some(reply) = server.on_frame(&to_server, t, od) else {
            panic!("server did not answer {to_server:?}");
        };
        match client.on_frame(&reply, t) {
            SdoStep::Send(f) => to_server = f,
            other => return (other, sent),
        }
    }
    panic!("transfer did not end")
}

#[test]
fn expedited_download_and_upload() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    let f = c.download(0x6060, 0, &[8], Duration::ZERO).unwrap();
    assert_eq!(f.id().raw(), 0x605);
    assert_eq!(
        f.data(),
        &[0x2F, 0x60, 0x60, 0, 8, 0, 0, 0],
        "1 byte: n=3, e, s"
    );
    assert_eq!(run(&mut c, &mut s, &mut od, f), (SdoStep::Downloaded, 1));
    let f = c.upload(0x1000, 0, Duration::ZERO).unwrap();
    assert_eq!(f.data()[0], 0x40);
    assert_eq!(
        run(&mut c, &mut s, &mut od, f),
        (SdoStep::Uploaded(vec![0x92, 0x01, 0x02, 0x00]), 1)
    );
    assert_eq!(od.0[&(0x6060, 0)], vec![8]);
}

#[test]
fn segmented_upload_and_download_of_21_and_15_bytes() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    let f = c.upload(0x1008, 0, Duration::ZERO).unwrap();
    let (step, frames) = run(&mut c, &mut s, &mut od, f);
    assert_eq!(step, SdoStep::Uploaded(b"hytask loopback drive".to_vec()));
    assert_eq!(frames, 4, "initiate + 3 segments of 7");
    let value: Vec<u8> = (0..15).collect();
    let f = c.download(0x2010, 1, &value, Duration::ZERO).unwrap();
    assert_eq!(f.data(), &[0x21, 0x10, 0x20, 1, 15, 0, 0, 0]);
    assert_eq!(run(&mut c, &mut s, &mut od, f), (SdoStep::Downloaded, 4));
    assert_eq!(od.0[&(0x2010, 1)], value);
}

#[test]
fn server_abort_is_decoded_to_a_named_error() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    let f = c
        .download(0x1000, 0, &[1, 2, 3, 4], Duration::ZERO)
        .unwrap();
    let (step, _) = run(&mut c, &mut s, &mut od, f);
    let SdoStep::Failed { error, abort: None } = step else {
        panic!("{step:?}")
    };
    assert_eq!(
        error,
        CanOpenError::SdoAbort {
            node: node(),
            index: 0x1000,
            sub: 0,
            abort: SdoAbortCode::ReadOnly
        }
    );
    assert_eq!(error.kind(), ErrorKind::Unsupported);
    assert_eq!(
        error.to_string(),
        "node 5: SDO 1000:00 aborted: abort 0x06010002: attempt to write a read only object"
    );
    let f = c.upload(0x1234, 7, Duration::ZERO).unwrap();
    assert!(matches!(
        run(&mut c, &mut s, &mut od, f).0,
        SdoStep::Failed {
            error: CanOpenError::SdoAbort {
                abort: SdoAbortCode::ObjectDoesNotExist,
                ..
            },
            ..
        }
    ));
}

#[test]
fn client_detects_a_repeated_toggle_and_aborts() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    let f = c.upload(0x1008, 0, Duration::ZERO).unwrap();
    let init = s.on_frame(&f, Duration::ZERO, &mut od).unwrap();
    let SdoStep::Send(seg_req) = c.on_frame(&init, Duration::ZERO) else {
        panic!()
    };
    let seg1 = s.on_frame(&seg_req, Duration::ZERO, &mut od).unwrap();
    let SdoStep::Send(_) = c.on_frame(&seg1, Duration::ZERO) else {
        panic!()
    };
    // The server repeats segment 1 (toggle 0) where toggle 1 is due.
    let SdoStep::Failed {
        error,
        abort: Some(a),
    } = c.on_frame(&seg1, Duration::ZERO)
    else {
        panic!()
    };
    assert!(matches!(
        error,
        CanOpenError::SdoAbort {
            abort: SdoAbortCode::ToggleBitNotAlternated,
            ..
        }
    ));
    assert_eq!(a.data(), &[0x80, 0x08, 0x10, 0, 0x00, 0x00, 0x03, 0x05]);
    assert!(!c.is_busy());
}

#[test]
fn server_detects_a_repeated_toggle() {
    let (mut s, mut od) = (SdoServer::new(node()), od());
    let mut c = SdoClient::new(node());
    let f = c.download(0x2010, 0, &[0; 20], Duration::ZERO).unwrap();
    s.on_frame(&f, Duration::ZERO, &mut od).unwrap();
    let bad = sdo_frame(node(), RX, [0x10, 1, 2, 3, 4, 5, 6, 7]);
    let a = s.on_frame(&bad, Duration::ZERO, &mut od).unwrap();
    assert_eq!(a.id().raw(), 0x585);
    assert_eq!(&a.data()[..4], &[0x80, 0x10, 0x20, 0]);
    assert_eq!(
        u32::from_le_bytes([a.data()[4], a.data()[5], a.data()[6], a.data()[7]]),
        0x0503_0000
    );
}

#[test]
fn silent_server_times_out_with_abort_frame() {
    let mut c = SdoClient::with_timeout(node(), Duration::from_millis(100));
    c.upload(0x6041, 0, Duration::from_millis(1000)).unwrap();
    assert!(matches!(
        c.download(0x6040, 0, &[6, 0], Duration::from_millis(1001)),
        Err(CanOpenError::SdoBusy { .. })
    ));
    assert_eq!(c.poll(Duration::from_millis(1100)), None);
    let Some(SdoStep::Failed {
        error,
        abort: Some(a),
    }) = c.poll(Duration::from_millis(1101))
    else {
        panic!()
    };
    assert_eq!(error.kind(), ErrorKind::Timeout);
    assert_eq!(
        error.to_string(),
        "node 5: SDO 6041:00 timed out after 100 ms"
    );
    assert_eq!(&a.data()[4..], &0x0504_0000u32.to_le_bytes());
    assert!(!c.is_busy());
}

#[test]
fn server_times_out_a_stalled_segmented_transfer_and_refuses_block_transfer() {
    let (mut s, mut od) = (SdoServer::new(node()), od());
    let mut c = SdoClient::new(node());
    let f = c.upload(0x1008, 0, Duration::ZERO).unwrap();
    s.on_frame(&f, Duration::ZERO, &mut od).unwrap();
    assert_eq!(s.poll(DEFAULT_TIMEOUT), None);
    let a = s.poll(DEFAULT_TIMEOUT + Duration::from_millis(1)).unwrap();
    assert_eq!(&a.data()[4..], &0x0504_0000u32.to_le_bytes());
    let block = sdo_frame(node(), RX, [0xC6, 0x08, 0x10, 0, 0, 0, 0, 0]);
    let a = s.on_frame(&block, Duration::ZERO, &mut od).unwrap();
    assert_eq!(&a.data()[4..], &0x0504_0001u32.to_le_bytes());
}

#[test]
fn frames_for_other_nodes_are_ignored() {
    let mut c = SdoClient::new(node());
    c.upload(0x6041, 0, Duration::ZERO).unwrap();
    let other = sdo_frame(
        NodeId::new(6).unwrap(),
        TX,
        [0x4B, 0x41, 0x60, 0, 1, 2, 0, 0],
    );
    assert_eq!(c.on_frame(&other, Duration::ZERO), SdoStep::Ignored);
    assert!(c.is_busy());
}
