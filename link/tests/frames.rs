//! The framing under bad input: every flipped bit, dropped byte, truncation, oversize frame,
//! junk between frames, unknown request and wrong version is refused with a typed error, never
//! decoded as another request, and the next good frame decodes at once; whatever decodes (a
//! random body behind a valid CRC) is exactly the bytes it was read from.

use proptest::prelude::*;
use saw_core::scene::default_config;
use saw_core::texture::lines::MAX_LINES;
use saw_link::frame::{self, Receiver, MAX_ENCODED, MAX_PAYLOAD};
use saw_link::msg::{Header, LinkError, Request, PROTOCOL_VERSION};

fn header(seq: u32) -> Header {
    Header {
        version: PROTOCOL_VERSION,
        seq,
    }
}

fn encode(seq: u32, req: &Request) -> Vec<u8> {
    let mut out = [0u8; MAX_ENCODED];
    let n = frame::encode(&header(seq), req, &mut out).unwrap();
    out[..n].to_vec()
}

/// Feeds `bytes`; returns each frame's outcome: the request decoded, or the error.
fn feed(bytes: &[u8]) -> Vec<Result<(u32, Request), LinkError>> {
    let mut rx = Receiver::<MAX_ENCODED>::default();
    let mut out = Vec::new();
    for &b in bytes {
        match rx.push(b) {
            None => {}
            Some(Ok(len)) => out.push(
                frame::request(rx.payload(len))
                    .map(|(h, r)| (h.seq, r))
                    .map_err(|r| r.error),
            ),
            Some(Err(e)) => out.push(Err(e)),
        }
    }
    out
}

#[test]
fn every_request_round_trips() {
    let reqs = saw_link::testing::every_request();
    // One per variant: VARIANTS must count them, or "unknown request" would refuse a real one.
    assert_eq!(reqs.len() as u32, Request::VARIANTS);
    for (i, req) in reqs.iter().enumerate() {
        let got = feed(&encode(i as u32 + 7, req));
        assert_eq!(got, vec![Ok((i as u32 + 7, req.clone()))]);
    }
}

#[test]
fn every_scene_file_round_trips_and_the_largest_scene_fits() {
    let timer = saw_core::burst::BurstTimer {
        clock_hz: 90_000_000,
        counter_bits: 32,
        max_burst_hz: 2_000,
    };
    let (mut n, mut n2) = (0, 0);
    for entry in std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes")).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        // A 2D scene (issue #36's `scenes/2d-*.toml`) rides in `LoadScene2d` with its plate.
        let sensor = saw_core::scene_file::sensor_of(&path.display().to_string(), &text);
        if sensor == Ok(saw_core::scene_file::SensorKind::FourWire) {
            let scene = saw_link::testing::plane_scene(&path.display().to_string(), &text);
            let req = Request::LoadScene2d(scene);
            assert_eq!(
                feed(&encode(1, &req)),
                vec![Ok((1, req))],
                "{}",
                path.display()
            );
            n2 += 1;
            continue;
        }
        let config =
            saw_core::scene_file::load_for_board(&path.display().to_string(), &text, timer, 100)
                .unwrap();
        let req = Request::LoadScene(config);
        assert_eq!(
            feed(&encode(1, &req)),
            vec![Ok((1, req))],
            "{}",
            path.display()
        );
        n += 1;
    }
    assert!(n >= 5, "{n} scene files");
    assert!(n2 >= 2, "{n2} 2D scene files");

    // The largest a Config gets: 8 random regions (the widest texture), every line.
    let big = saw_core::scene::largest_config();
    assert_eq!(big.scene.textures.len(), 8);
    assert_eq!(big.scene.boundaries_um.len(), 7);
    assert_eq!(big.scene.lines.positions_um.len(), MAX_LINES);
    let len = postcard::to_allocvec(&Request::LoadScene(big.clone()))
        .unwrap()
        .len();
    assert!(len + 16 < MAX_PAYLOAD, "largest scene {len} bytes");
    let req = Request::LoadScene(big);
    assert_eq!(feed(&encode(3, &req)), vec![Ok((3, req))]);

    // The largest 2D scene (issue #36): 1 460 bytes, which set MAX_PAYLOAD (768 before).
    let big = saw_link::testing::largest_plane_scene();
    assert_eq!(big.config.scene.windows.len(), 8);
    assert!(big
        .config
        .scene
        .windows
        .iter()
        .all(|w| w.outline.vertices.len() == 16));
    assert_eq!(big.config.scene.free_edges.len(), 32);
    let req = Request::LoadScene2d(big);
    let len = postcard::to_allocvec(&req).unwrap().len();
    assert!(
        len > 768 && len + 16 < MAX_PAYLOAD,
        "largest 2D scene {len} bytes"
    );
    assert_eq!(feed(&encode(4, &req)), vec![Ok((4, req))]);
}

#[test]
fn a_flipped_bit_anywhere_is_refused_and_the_next_frame_decodes() {
    let good = encode(2, &Request::Hello);
    let victim = encode(
        1,
        &Request::MoveBoundary {
            index: 0,
            at_um: 20_000,
        },
    );
    for bit in 0..victim.len() * 8 {
        let mut bytes = victim.clone();
        bytes[bit / 8] ^= 1 << (bit % 8);
        bytes.push(0); // as a host sends: a zero before each frame
        bytes.extend_from_slice(&good);
        let got = feed(&bytes);
        // The flipped frame never decodes (a flip to or from zero may split it in two or join
        // it to the next; each piece is refused), and the good one always does.
        assert_eq!(
            got.last(),
            Some(&Ok((2, Request::Hello))),
            "bit {bit}: {got:?}"
        );
        for r in &got[..got.len() - 1] {
            assert!(r.is_err(), "bit {bit} decoded as {r:?}");
        }
    }
}

#[test]
fn a_dropped_byte_or_a_truncated_frame_is_refused() {
    let good = encode(2, &Request::Hello);
    let victim = encode(1, &Request::LoadScene(default_config()));
    for i in 0..victim.len() - 1 {
        let mut dropped = victim.clone();
        dropped.remove(i);
        let mut truncated = victim[..i].to_vec();
        truncated.push(0);
        for bytes in [dropped, truncated] {
            let mut bytes = bytes;
            bytes.push(0);
            bytes.extend_from_slice(&good);
            let got = feed(&bytes);
            assert_eq!(
                got.last(),
                Some(&Ok((2, Request::Hello))),
                "byte {i}: {got:?}"
            );
            assert!(
                got[..got.len() - 1].iter().all(|r| r.is_err()),
                "byte {i}: {got:?}"
            );
        }
    }
}

#[test]
fn an_oversize_frame_is_skipped_to_its_end() {
    let mut bytes = vec![0x55; MAX_ENCODED + 100];
    bytes.push(0);
    bytes.extend_from_slice(&encode(9, &Request::Save));
    assert_eq!(
        feed(&bytes),
        vec![
            Err(LinkError::Oversize {
                max_bytes: MAX_ENCODED as u16
            }),
            Ok((9, Request::Save))
        ]
    );
}

/// A frame with a valid CRC around `body` (bytes after the header).
fn raw_frame(version: u16, seq: u32, body: &[u8]) -> Vec<u8> {
    let mut payload = postcard::to_allocvec(&Header { version, seq }).unwrap();
    payload.extend_from_slice(body);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&payload);
    payload.extend_from_slice(&crc.to_le_bytes());
    let mut out = cobs::encode_vec(&payload);
    out.push(0);
    out
}

#[test]
fn unknown_request_wrong_version_and_bad_fields_are_typed() {
    assert_eq!(
        feed(&raw_frame(PROTOCOL_VERSION, 4, &[42])),
        vec![Err(LinkError::UnknownRequest { variant: 42 })]
    );
    let hello = postcard::to_allocvec(&Request::Hello).unwrap();
    assert_eq!(
        feed(&raw_frame(PROTOCOL_VERSION + 1, 5, &hello)),
        vec![Err(LinkError::WrongVersion {
            ours: PROTOCOL_VERSION,
            theirs: PROTOCOL_VERSION + 1
        })]
    );
    // MoveBoundary with its fields cut off.
    assert_eq!(
        feed(&raw_frame(PROTOCOL_VERSION, 6, &[3])),
        vec![Err(LinkError::Malformed)]
    );
    // Too short to hold a header and a CRC.
    let mut short = cobs::encode_vec(&[1, 2, 3]);
    short.push(0);
    assert_eq!(feed(&short), vec![Err(LinkError::Truncated { bytes: 3 })]);
    // The wrong-version refusal keeps the request's number, so the reply matches it.
    let r = frame::request(&{
        let mut p = postcard::to_allocvec(&Header {
            version: 9,
            seq: 77,
        })
        .unwrap();
        p.push(0);
        p
    })
    .unwrap_err();
    assert_eq!(r.seq, Some(77));
}

proptest! {
    /// Junk of any kind between frames costs only itself: every good frame after a zero decodes.
    #[test]
    fn junk_between_frames_never_costs_a_good_frame(junk in proptest::collection::vec(any::<u8>(), 0..300)) {
        let mut bytes = encode(1, &Request::Hello);
        bytes.extend_from_slice(&junk);
        bytes.push(0);
        bytes.extend_from_slice(&encode(2, &Request::Save));
        let got = feed(&bytes);
        prop_assert_eq!(got.first(), Some(&Ok((1, Request::Hello))));
        prop_assert_eq!(got.last(), Some(&Ok((2, Request::Save))));
    }

    /// Any bytes at all: the receiver never panics, and whatever decodes is a request that
    /// frames back to itself (random bytes rarely pass the CRC, so the test below gives the
    /// decoder bodies that do).
    #[test]
    fn any_bytes_are_answered_without_a_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
        for got in feed(&bytes) {
            if let Ok((seq, req)) = got {
                prop_assert_eq!(feed(&encode(seq, &req)), vec![Ok((seq, req))]);
            }
        }
    }

    /// A random body behind a valid header and CRC (its first byte a known request's number, so
    /// the decoder gets past the variant): whatever decodes is exactly the bytes it was read
    /// from — postcard encodes the request back to the body's first bytes, and framed again it
    /// decodes to the same request. A decoder that read fields loosely (a bool from any non-zero
    /// byte, an over-long varint, a value clamped into range) would map two byte strings to one
    /// request, and fail here. Bytes after the request are left unread (postcard stops at the
    /// request's end), so only the bytes it consumed are compared.
    #[test]
    fn whatever_decodes_from_a_random_body_encodes_back_to_it(
        variant in 0..Request::VARIANTS as u8,
        rest in proptest::collection::vec(any::<u8>(), 0..200),
    ) {
        let mut body = vec![variant];
        body.extend_from_slice(&rest);
        let got = feed(&raw_frame(PROTOCOL_VERSION, 11, &body));
        prop_assert_eq!(got.len(), 1);
        if let Ok((seq, req)) = &got[0] {
            prop_assert_eq!(*seq, 11);
            let (_, unread): (Request, &[u8]) = postcard::take_from_bytes(&body).unwrap();
            let read = &body[..body.len() - unread.len()];
            // Exactly those bytes, but for over-long varints: postcard reads `128, 0` as 0
            // (`postcard_reads_an_over_long_varint_as_its_value` below), the same value.
            let again = postcard::to_allocvec(req).unwrap();
            if again != read {
                prop_assert!(again.len() < read.len(), "{:?}", req);
                prop_assert_eq!(postcard::from_bytes::<Request>(read).unwrap(), req.clone());
            }
            prop_assert_eq!(feed(&encode(*seq, req)), vec![Ok((*seq, req.clone()))]);
        }
    }
}

/// The random-body property above is not vacuous: enough of its bodies decode to a request
/// (a body of zeros decodes as most requests' smallest form) that a loose decoder would show.
#[test]
fn random_bodies_do_decode() {
    use proptest::strategy::ValueTree;
    use proptest::test_runner::TestRunner;
    let mut runner = TestRunner::deterministic();
    let strategy = (
        0..Request::VARIANTS as u8,
        proptest::collection::vec(any::<u8>(), 0..200),
    );
    let mut decoded = 0;
    for _ in 0..256 {
        let (variant, rest) = strategy.new_tree(&mut runner).unwrap().current();
        let mut body = vec![variant];
        body.extend_from_slice(&rest);
        if let [Ok(_)] = feed(&raw_frame(PROTOCOL_VERSION, 11, &body))[..] {
            decoded += 1;
        }
    }
    assert!(decoded >= 64, "{decoded} of 256 random bodies decoded");
}

/// Found by the property above once `MoveWindow` (a short request of i32 varints, issue #36)
/// made random bodies decode more often: postcard does not insist on the shortest varint, so
/// `128, 0` reads as 0, in a 1D request as in a 2D one. The value is the same (a corrupted byte
/// is still the CRC's to catch); refusing non-canonical bodies would need the board to encode
/// every request again. Recorded here, not changed.
#[test]
fn postcard_reads_an_over_long_varint_as_its_value() {
    let canonical = encode(5, &Request::MoveBoundary { index: 0, at_um: 0 });
    let got = feed(&raw_frame(PROTOCOL_VERSION, 5, &[3, 0, 128, 0]));
    assert_eq!(
        got,
        vec![Ok((5, Request::MoveBoundary { index: 0, at_um: 0 }))]
    );
    assert_eq!(feed(&canonical), got);
}
