use super::*;
use crate::canopen::CanOpenError;
use crate::error::{Error, ErrorKind};
use std::collections::BTreeMap;
use std::time::Duration;

struct Od(BTreeMap<(u16, u8), Vec<u8>>);

impl ObjectAccess for Od {
    fn read(&mut self, index: u16, sub: u8, out: &mut Vec<u8>) -> Result<(), SdoAbortCode> {
        let v = self
            .0
            .get(&(index, sub))
            .ok_or(SdoAbortCode::ObjectDoesNotExist)?;
        out.extend_from_slice(v);
        Ok(())
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
    exchange(client, server, od, first, |_| false)
}

/// [`run`] for every kind of transfer: frames go through a queue each way, a sub-block or
/// a server's burst as a whole, and `lose` drops frames (in either direction) it returns
/// true for. A block upload's end confirmation is delivered to the server too.
fn exchange(
    client: &mut SdoClient,
    server: &mut SdoServer,
    od: &mut Od,
    first: CanFrame,
    mut lose: impl FnMut(&CanFrame) -> bool,
) -> (SdoStep, usize) {
    let t = Duration::ZERO;
    let mut to_server = std::collections::VecDeque::from([first]);
    let mut sent = 1;
    for _ in 0..100_000 {
        let Some(f) = to_server.pop_front() else {
            panic!("transfer stalled: no frame in flight")
        };
        if lose(&f) {
            continue;
        }
        let mut replies: Vec<CanFrame> = server.on_frame(&f, t, od).into_iter().collect();
        replies.extend(std::iter::from_fn(|| server.next_burst()));
        for r in replies.iter().filter(|r| !lose(r)) {
            match client.on_frame(r, t) {
                SdoStep::Ignored => {}
                SdoStep::Send(f) => {
                    sent += 1;
                    to_server.push_back(f);
                }
                SdoStep::SendBlock(frames) => {
                    sent += frames.len();
                    to_server.extend(frames);
                }
                SdoStep::BlockUploaded { value, confirm } => {
                    assert_eq!(server.on_frame(&confirm, t, od), None);
                    return (SdoStep::Uploaded(value), sent + 1);
                }
                other => return (other, sent),
            }
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
fn server_times_out_a_stalled_segmented_transfer_and_refuses_an_unknown_command() {
    let (mut s, mut od) = (SdoServer::new(node()), od());
    let mut c = SdoClient::new(node());
    let f = c.upload(0x1008, 0, Duration::ZERO).unwrap();
    s.on_frame(&f, Duration::ZERO, &mut od).unwrap();
    assert_eq!(s.poll(DEFAULT_TIMEOUT), None);
    let a = s.poll(DEFAULT_TIMEOUT + Duration::from_millis(1)).unwrap();
    assert_eq!(&a.data()[4..], &0x0504_0000u32.to_le_bytes());
    let unknown = sdo_frame(node(), RX, [0xE0, 0x08, 0x10, 0, 0, 0, 0, 0]);
    let a = s.on_frame(&unknown, Duration::ZERO, &mut od).unwrap();
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

/// A server without block transfer, as python-canopen's and many drives': it answers
/// every block request with abort 0x05040001.
fn refuse_block(server: &mut SdoServer, f: &CanFrame, od: &mut Od) -> Option<CanFrame> {
    let cmd = f.data()[0] >> 5;
    if (cmd == 5 || cmd == 6) && f.id().raw() == node().cob(RX).raw() {
        let (index, sub) = multiplexer(f.data());
        return Some(abort_frame(
            node(),
            TX,
            index,
            sub,
            SdoAbortCode::InvalidCommandSpecifier,
        ));
    }
    server.on_frame(f, Duration::ZERO, od)
}

fn long_value(len: usize) -> Vec<u8> {
    (0..len).map(|i| (i * 7 + 3) as u8).collect()
}

#[test]
fn block_download_of_1000_bytes_takes_two_sub_blocks_with_crc() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    let value = long_value(1000);
    let f = c.download(0x2010, 2, &value, Duration::ZERO).unwrap();
    assert_eq!(
        f.data(),
        &[0xC6, 0x10, 0x20, 2, 0xE8, 0x03, 0, 0],
        "ccs 6, CRC, size 1000"
    );
    let (step, frames) = run(&mut c, &mut s, &mut od, f);
    assert_eq!(step, SdoStep::Downloaded);
    // initiate + 143 segments (127 + 16) + end.
    assert_eq!(frames, 1 + 143 + 1);
    assert_eq!(od.0[&(0x2010, 2)], value);
    assert!(!c.block_refused());
}

#[test]
fn block_upload_of_300_bytes_checks_the_crc() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    let value = long_value(300);
    od.0.insert((0x2011, 0), value.clone());
    let f = c.upload_block(0x2011, 0, Duration::ZERO).unwrap();
    assert_eq!(f.data(), &[0xA4, 0x11, 0x20, 0, 127, 32, 0, 0]);
    // initiate, start, one acknowledgement, end confirmation.
    assert_eq!(
        run(&mut c, &mut s, &mut od, f),
        (SdoStep::Uploaded(value.clone()), 4)
    );
    // A corrupted byte in flight (the server's CRC covers what it sent): CRC error.
    let f = c.upload_block(0x2011, 0, Duration::ZERO).unwrap();
    let mut s2 = SdoServer::new(node());
    let _ = s2.on_frame(&f, Duration::ZERO, &mut od).unwrap();
    let start = sdo_frame(node(), RX, [0xA3, 0, 0, 0, 0, 0, 0, 0]);
    assert!(matches!(
        c.on_frame(
            &s2.on_frame(&f, Duration::ZERO, &mut od).unwrap(),
            Duration::ZERO
        ),
        SdoStep::Send(_)
    ));
    let mut segs: Vec<CanFrame> = s2
        .on_frame(&start, Duration::ZERO, &mut od)
        .into_iter()
        .collect();
    segs.extend(std::iter::from_fn(|| s2.next_burst()));
    assert_eq!(segs.len(), 43);
    let mut bad = segs[5].data().to_vec();
    bad[3] ^= 0x40;
    segs[5] = sdo_frame(node(), TX, bad.try_into().unwrap());
    let mut ack = None;
    for g in &segs {
        if let SdoStep::Send(a) = c.on_frame(g, Duration::ZERO) {
            ack = Some(a);
        }
    }
    let end = s2.on_frame(&ack.unwrap(), Duration::ZERO, &mut od).unwrap();
    assert_eq!(
        end.data()[0],
        0xC1 | (1 << 2),
        "300 = 42 * 7 + 6: one byte of padding"
    );
    let SdoStep::Failed {
        error,
        abort: Some(a),
    } = c.on_frame(&end, Duration::ZERO)
    else {
        panic!()
    };
    assert!(matches!(
        error,
        CanOpenError::SdoAbort {
            abort: SdoAbortCode::CrcError,
            ..
        }
    ));
    assert_eq!(&a.data()[4..], &0x0504_0004u32.to_le_bytes());
}

#[test]
fn block_upload_of_a_short_value_switches_to_the_normal_protocol() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    let f = c.upload_block(0x1008, 0, Duration::ZERO).unwrap();
    // 21 bytes <= pst 32: the server answers a segmented upload.
    assert_eq!(
        run(&mut c, &mut s, &mut od, f),
        (SdoStep::Uploaded(b"hytask loopback drive".to_vec()), 4)
    );
    let f = c.upload_block(0x1000, 0, Duration::ZERO).unwrap();
    assert_eq!(
        run(&mut c, &mut s, &mut od, f).0,
        SdoStep::Uploaded(vec![0x92, 0x01, 0x02, 0x00])
    );
}

#[test]
fn lost_segments_are_resent_from_the_acknowledged_one() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    let value = long_value(200);
    // Download: the first time segment 5 of a sub-block goes out, it is lost.
    let mut lost = false;
    let f = c.download(0x2012, 0, &value, Duration::ZERO).unwrap();
    let lose = |f: &CanFrame| {
        let hit = !lost && f.id().raw() == 0x605 && f.data()[0] == 5;
        lost |= hit;
        hit
    };
    let (step, frames) = exchange(&mut c, &mut s, &mut od, f, lose);
    assert_eq!(step, SdoStep::Downloaded);
    // 29 segments, of which 25 (5..=29) went twice.
    assert_eq!(frames, 1 + 29 + 25 + 1);
    assert_eq!(od.0[&(0x2012, 0)], value);
    // Upload: segment 10 from the server is lost once.
    let mut lost = false;
    let f = c.upload_block(0x2012, 0, Duration::ZERO).unwrap();
    let lose = |f: &CanFrame| {
        let hit = !lost && f.id().raw() == 0x585 && f.data()[0] == 10;
        lost |= hit;
        hit
    };
    let (step, frames) = exchange(&mut c, &mut s, &mut od, f, lose);
    assert_eq!(step, SdoStep::Uploaded(value));
    assert_eq!(
        frames, 5,
        "initiate, start, two acknowledgements, confirmation"
    );
}

#[test]
fn a_server_without_block_transfer_gets_the_transfer_segmented() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    let value = long_value(40);
    let first = c.download(0x2013, 0, &value, Duration::ZERO).unwrap();
    assert_eq!(first.data()[0] >> 5, 6, "block download tried first");
    let abort = refuse_block(&mut s, &first, &mut od).unwrap();
    let SdoStep::Send(segmented) = c.on_frame(&abort, Duration::ZERO) else {
        panic!("no fallback")
    };
    assert_eq!(segmented.data(), &[0x21, 0x13, 0x20, 0, 40, 0, 0, 0]);
    assert!(c.block_refused());
    assert_eq!(
        run(&mut c, &mut s, &mut od, segmented).0,
        SdoStep::Downloaded
    );
    assert_eq!(od.0[&(0x2013, 0)], value);
    // Later transfers go segmented straight away.
    let f = c.download(0x2013, 0, &value, Duration::ZERO).unwrap();
    assert_eq!(f.data()[0], 0x21);
    assert_eq!(run(&mut c, &mut s, &mut od, f).0, SdoStep::Downloaded);
    let f = c.upload_block(0x2013, 0, Duration::ZERO).unwrap();
    assert_eq!(f.data()[0], 0x40);
    // Upload fallback on a fresh client.
    let mut c = SdoClient::new(node());
    let first = c.upload_block(0x2013, 0, Duration::ZERO).unwrap();
    let abort = refuse_block(&mut s, &first, &mut od).unwrap();
    let SdoStep::Send(normal) = c.on_frame(&abort, Duration::ZERO) else {
        panic!("no fallback")
    };
    assert_eq!(normal.data()[0], 0x40);
    assert_eq!(
        run(&mut c, &mut s, &mut od, normal).0,
        SdoStep::Uploaded(value)
    );
    // Another abort is still an error, and block can be switched off.
    let mut c = SdoClient::new(node()).with_block_threshold(None);
    let f = c
        .download(0x2013, 0, &long_value(40), Duration::ZERO)
        .unwrap();
    assert_eq!(f.data()[0], 0x21);
}

#[test]
fn server_checks_the_crc_and_the_size_of_a_block_download() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    let value = long_value(50);
    let f = c.download(0x2014, 0, &value, Duration::ZERO).unwrap();
    let r = s.on_frame(&f, Duration::ZERO, &mut od).unwrap();
    assert_eq!(r.data()[..5], [0xA4, 0x14, 0x20, 0, 127]);
    let SdoStep::SendBlock(segs) = c.on_frame(&r, Duration::ZERO) else {
        panic!()
    };
    assert_eq!(segs.len(), 8);
    let mut ack = None;
    for g in &segs {
        ack = s.on_frame(g, Duration::ZERO, &mut od).or(ack);
    }
    let SdoStep::Send(end) = c.on_frame(&ack.unwrap(), Duration::ZERO) else {
        panic!()
    };
    let mut bad = end.data().to_vec();
    bad[1] ^= 1;
    let a = s
        .on_frame(
            &sdo_frame(node(), RX, bad.try_into().unwrap()),
            Duration::ZERO,
            &mut od,
        )
        .unwrap();
    assert_eq!(&a.data()[4..], &0x0504_0004u32.to_le_bytes());
    assert!(!od.0.contains_key(&(0x2014, 0)), "nothing stored");
}

#[test]
fn a_block_upload_still_going_out_is_not_a_silent_client() {
    let (mut c, mut s, mut od) = (SdoClient::new(node()), SdoServer::new(node()), od());
    od.0.insert((0x2011, 0), long_value(500));
    let t = Duration::ZERO;
    let init = s
        .on_frame(&c.upload_block(0x2011, 0, t).unwrap(), t, &mut od)
        .unwrap();
    let SdoStep::Send(start) = c.on_frame(&init, t) else {
        panic!()
    };
    assert!(s.on_frame(&start, t, &mut od).is_some(), "first segment");
    // The caller's transmit queue holds the rest back for a long while.
    let late = DEFAULT_TIMEOUT * 3;
    assert_eq!(s.poll(late), None, "segments left to send: no timeout");
    let rest = std::iter::from_fn(|| s.next_burst()).count();
    assert_eq!(rest, 71, "72 segments of 7 bytes");
    assert_eq!(s.poll(late + DEFAULT_TIMEOUT), None);
    let a = s
        .poll(late + DEFAULT_TIMEOUT + Duration::from_millis(1))
        .unwrap();
    assert_eq!(
        &a.data()[4..],
        &0x0504_0000u32.to_le_bytes(),
        "then the ack is late"
    );
}
