//! The protocol's frame codec: pure, no I/O (see `PROTOCOL.md`). Both ends use it: the
//! simulator encodes packets and decodes commands, the device the other way round.

/// First header byte.
pub const SYNC_A: u8 = 0xFA;
/// Second header byte.
pub const SYNC_B: u8 = 0xFB;
/// Largest COUNT (payload + checksum).
pub const MAX_COUNT: usize = 200;
/// Most sightings in a barcode packet.
pub const MAX_SIGHTINGS: usize = 8;
/// Sonars on the robot's ring, 15° apart, sonar 0 facing forward (a status packet reports
/// any subset of them by index).
pub const SONARS: usize = 24;

const ARG_POS: u8 = 0x3B;
const ARG_NEG: u8 = 0x1B;
const ARG_STR: u8 = 0x2B;
/// Longest text a SAY command carries (bytes).
pub const MAX_SAY: usize = 64;

/// Why bytes or a payload were refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum CodecError {
    /// COUNT out of range.
    #[error("frame COUNT {count} outside 3..={MAX_COUNT}")]
    BadCount {
        /// The COUNT byte.
        count: u8,
    },
    /// Checksum mismatch.
    #[error("bad checksum: frame says {sent:#06x}, payload sums to {computed:#06x}")]
    BadChecksum {
        /// In the frame.
        sent: u16,
        /// Computed.
        computed: u16,
    },
    /// A payload too long to frame.
    #[error("payload of {len} bytes is longer than {} bytes", MAX_COUNT - 2)]
    TooLong {
        /// Its length.
        len: usize,
    },
    /// A payload whose first byte names nothing known.
    #[error("unknown {what} {code:#04x}")]
    Unknown {
        /// "command" or "packet type".
        what: &'static str,
        /// The byte.
        code: u8,
    },
    /// A payload shorter than its type needs.
    #[error("{what} payload too short: {len} bytes")]
    Short {
        /// What was being decoded.
        what: &'static str,
        /// Its length.
        len: usize,
    },
    /// An argument of an unknown type byte.
    #[error("unknown argument type {0:#04x}")]
    BadArg(u8),
}

/// The protocol checksum of a payload.
pub fn checksum(payload: &[u8]) -> u16 {
    let mut c: u16 = 0;
    let mut pairs = payload.chunks_exact(2);
    for p in &mut pairs {
        c = c.wrapping_add(u16::from_be_bytes([p[0], p[1]]));
    }
    if let [last] = pairs.remainder() {
        c ^= u16::from(*last);
    }
    c
}

/// Frames a payload.
pub fn frame(payload: &[u8]) -> Result<Vec<u8>, CodecError> {
    if payload.is_empty() || payload.len() > MAX_COUNT - 2 {
        return Err(CodecError::TooLong { len: payload.len() });
    }
    let mut out = Vec::with_capacity(payload.len() + 5);
    out.extend_from_slice(&[SYNC_A, SYNC_B, (payload.len() + 2) as u8]);
    out.extend_from_slice(payload);
    out.extend_from_slice(&checksum(payload).to_be_bytes());
    Ok(out)
}

/// Counters of what the decoder met.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DecodeStats {
    /// Good frames.
    pub frames: u64,
    /// Bytes skipped outside frames.
    pub garbage: u64,
    /// Frames dropped for a bad checksum.
    pub bad_checksum: u64,
    /// Headers dropped for a bad COUNT.
    pub bad_count: u64,
}

/// Turns a byte stream into frames, resynchronising after garbage and errors.
#[derive(Debug, Default)]
pub struct Decoder {
    buf: Vec<u8>,
    /// What it met so far.
    pub stats: DecodeStats,
}

impl Decoder {
    /// Adds received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
        // A stream of pure garbage must not grow the buffer without bound.
        if self.buf.len() > 64 * 1024 {
            let cut = self.buf.len() - MAX_COUNT - 3;
            self.stats.garbage += cut as u64;
            self.buf.drain(..cut);
        }
    }

    /// The next payload, an error for a dropped frame, or `None` when more bytes are needed.
    pub fn next_frame(&mut self) -> Option<Result<Vec<u8>, CodecError>> {
        let start = self.buf.windows(2).position(|w| w == [SYNC_A, SYNC_B]);
        let Some(start) = start else {
            // Keep a trailing 0xFA: it may begin the next header.
            let keep = usize::from(self.buf.last() == Some(&SYNC_A));
            let skip = self.buf.len() - keep;
            self.stats.garbage += skip as u64;
            self.buf.drain(..skip);
            return None;
        };
        if start > 0 {
            self.stats.garbage += start as u64;
            self.buf.drain(..start);
        }
        let count = *self.buf.get(2)?;
        if !(3..=MAX_COUNT as u8).contains(&count) {
            self.stats.bad_count += 1;
            self.buf.drain(..2);
            return Some(Err(CodecError::BadCount { count }));
        }
        let total = 3 + usize::from(count);
        if self.buf.len() < total {
            return None;
        }
        let payload = &self.buf[3..total - 2];
        let sent = u16::from_be_bytes([self.buf[total - 2], self.buf[total - 1]]);
        let computed = checksum(payload);
        if sent != computed {
            self.stats.bad_checksum += 1;
            // Resynchronise just past this header: a corrupted COUNT must not swallow the
            // frames that follow.
            self.buf.drain(..2);
            return Some(Err(CodecError::BadChecksum { sent, computed }));
        }
        let payload = payload.to_vec();
        self.buf.drain(..total);
        self.stats.frames += 1;
        Some(Ok(payload))
    }
}

/// A command, client to robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Handshake step 1, or keep-alive after the handshake.
    Sync0,
    /// Handshake step 2, or OPEN after the handshake.
    Sync1,
    /// Handshake step 3, or CLOSE after the handshake.
    Sync2,
    /// Motors on or off.
    Enable(bool),
    /// Translate velocity, mm/s.
    Vel(i16),
    /// Rotate velocity, 0.1 °/s.
    RVel(i16),
    /// Status period, ms.
    Period(u16),
    /// Watchdog time, ms: the robot stops when no command came for this long.
    Watchdog(u16),
    /// Lock-step only: advance this many ms of simulated time, then acknowledge
    /// ([`Packet::Stepped`]).
    Step(u16),
    /// One stroke of the button pusher (answered by [`Packet::Arm`]).
    Push,
    /// Speak and show a message (answered by [`Packet::Said`]).
    Say(Text),
}

/// A SAY command's text: at most [`MAX_SAY`] bytes, kept inline so commands stay `Copy`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Text {
    len: u8,
    bytes: [u8; MAX_SAY],
}

impl Text {
    /// The first [`MAX_SAY`] bytes of `s` (cut at a character boundary).
    pub fn new(s: &str) -> Text {
        let mut end = s.len().min(MAX_SAY);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        Text::from_bytes(&s.as_bytes()[..end])
    }

    /// The first [`MAX_SAY`] bytes of `b`.
    pub fn from_bytes(b: &[u8]) -> Text {
        let n = b.len().min(MAX_SAY);
        let mut bytes = [0; MAX_SAY];
        bytes[..n].copy_from_slice(&b[..n]);
        Text {
            len: n as u8,
            bytes,
        }
    }

    /// The bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..usize::from(self.len)]
    }

    /// The text (invalid UTF-8 replaced).
    pub fn to_string_lossy(&self) -> String {
        String::from_utf8_lossy(self.as_bytes()).into_owned()
    }
}

fn int_arg(v: i32) -> [u8; 3] {
    let (t, a) = if v >= 0 { (ARG_POS, v) } else { (ARG_NEG, -v) };
    let a = a.clamp(0, i32::from(u16::MAX)) as u16;
    let b = a.to_le_bytes();
    [t, b[0], b[1]]
}

impl Command {
    /// The command's payload.
    pub fn payload(self) -> Vec<u8> {
        let with = |cmd: u8, v: i32| {
            let mut p = vec![cmd];
            p.extend_from_slice(&int_arg(v));
            p
        };
        match self {
            Command::Sync0 => vec![0],
            Command::Sync1 => vec![1],
            Command::Sync2 => vec![2],
            Command::Enable(on) => with(4, i32::from(on)),
            Command::Vel(v) => with(11, i32::from(v)),
            Command::RVel(v) => with(21, i32::from(v)),
            Command::Period(ms) => with(60, i32::from(ms)),
            Command::Watchdog(ms) => with(62, i32::from(ms)),
            Command::Step(ms) => with(70, i32::from(ms)),
            Command::Push => vec![80],
            Command::Say(t) => {
                let b = t.as_bytes();
                let mut p = vec![81, ARG_STR, b.len() as u8];
                p.extend_from_slice(b);
                p
            }
        }
    }

    /// The command, framed.
    pub fn encode(self) -> Vec<u8> {
        // Command payloads are 1 or 4 bytes, or 3 + 64 at most (SAY): always frameable.
        frame(&self.payload()).unwrap_or_default()
    }

    /// Decodes a command payload.
    pub fn decode(p: &[u8]) -> Result<Command, CodecError> {
        let cmd = *p.first().ok_or(CodecError::Short {
            what: "command",
            len: 0,
        })?;
        let arg = || -> Result<i32, CodecError> {
            if p.len() < 4 {
                return Err(CodecError::Short {
                    what: "command",
                    len: p.len(),
                });
            }
            let v = i32::from(u16::from_le_bytes([p[2], p[3]]));
            match p[1] {
                ARG_POS => Ok(v),
                ARG_NEG => Ok(-v),
                t => Err(CodecError::BadArg(t)),
            }
        };
        let sat = |v: i32| v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16;
        Ok(match cmd {
            0 => Command::Sync0,
            1 => Command::Sync1,
            2 => Command::Sync2,
            4 => Command::Enable(arg()? != 0),
            11 => Command::Vel(sat(arg()?)),
            21 => Command::RVel(sat(arg()?)),
            60 => Command::Period(arg()?.clamp(0, i32::from(u16::MAX)) as u16),
            62 => Command::Watchdog(arg()?.clamp(0, i32::from(u16::MAX)) as u16),
            70 => Command::Step(arg()?.clamp(0, i32::from(u16::MAX)) as u16),
            80 => Command::Push,
            81 => {
                if p.len() < 3 {
                    return Err(CodecError::Short {
                        what: "say",
                        len: p.len(),
                    });
                }
                if p[1] != ARG_STR {
                    return Err(CodecError::BadArg(p[1]));
                }
                let n = usize::from(p[2]);
                if p.len() < 3 + n || n > MAX_SAY {
                    return Err(CodecError::Short {
                        what: "say text",
                        len: p.len(),
                    });
                }
                Command::Say(Text::from_bytes(&p[3..3 + n]))
            }
            code => {
                return Err(CodecError::Unknown {
                    what: "command",
                    code,
                });
            }
        })
    }
}

/// One barcode sighting.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sighting {
    /// Barcode id.
    pub id: u16,
    /// Bearing, 0.1°, counter-clockwise from the front.
    pub bearing: i16,
    /// Range, mm.
    pub range: u16,
}

/// The robot's status packet.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Status {
    /// Whether the robot moves.
    pub moving: bool,
    /// x, mm, 15 bits, wrapping.
    pub x: u16,
    /// y, mm, 15 bits, wrapping.
    pub y: u16,
    /// Heading, 1/4096 revolution.
    pub th: u16,
    /// Translate velocity, mm/s.
    pub vel: i16,
    /// Rotate velocity, 0.1 °/s.
    pub rvel: i16,
    /// Battery, 0.1 V.
    pub battery: u8,
    /// Bit 0 stall, bits 1..8 bumpers.
    pub flags: u16,
    /// New sonar readings: (number, range mm; 0 = no echo).
    pub sonars: Vec<(u8, u16)>,
}

/// A packet, robot to client.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Packet {
    /// Handshake echo (0, 1 or 2).
    Sync(u8),
    /// Status.
    Status(Status),
    /// Barcode sightings.
    Barcodes(Vec<Sighting>),
    /// Lock-step: a STEP is done; the robot's time now (ms since it started).
    Stepped(u32),
    /// The button pusher after a stroke.
    Arm {
        /// Strokes made since the robot started.
        strokes: u16,
        /// The button the last stroke pressed (its id; 0: it pressed none).
        pressed: u16,
    },
    /// Messages spoken since the robot started.
    Said(u16),
}

impl Packet {
    /// The packet's payload.
    pub fn payload(&self) -> Vec<u8> {
        match self {
            Packet::Sync(n) => vec![*n],
            Packet::Status(s) => {
                let mut p = vec![if s.moving { 0x32 } else { 0x33 }];
                for v in [s.x & 0x7fff, s.y & 0x7fff, s.th & 0x0fff] {
                    p.extend_from_slice(&v.to_le_bytes());
                }
                p.extend_from_slice(&s.vel.to_le_bytes());
                p.extend_from_slice(&s.rvel.to_le_bytes());
                p.push(s.battery);
                p.extend_from_slice(&s.flags.to_le_bytes());
                let n = s.sonars.len().min(24);
                p.push(n as u8);
                for (num, r) in &s.sonars[..n] {
                    p.push(*num);
                    p.extend_from_slice(&r.to_le_bytes());
                }
                p
            }
            Packet::Barcodes(b) => {
                let n = b.len().min(MAX_SIGHTINGS);
                let mut p = vec![0x40, n as u8];
                for s in &b[..n] {
                    p.extend_from_slice(&s.id.to_le_bytes());
                    p.extend_from_slice(&s.bearing.to_le_bytes());
                    p.extend_from_slice(&s.range.to_le_bytes());
                }
                p
            }
            Packet::Stepped(ms) => {
                let mut p = vec![0x50];
                p.extend_from_slice(&ms.to_le_bytes());
                p
            }
            Packet::Arm { strokes, pressed } => {
                let mut p = vec![0x60];
                p.extend_from_slice(&strokes.to_le_bytes());
                p.extend_from_slice(&pressed.to_le_bytes());
                p
            }
            Packet::Said(n) => {
                let mut p = vec![0x61];
                p.extend_from_slice(&n.to_le_bytes());
                p
            }
        }
    }

    /// The packet, framed.
    pub fn encode(&self) -> Vec<u8> {
        // At most 1 + 13 + 1 + 24·3 = 87 (status) or 2 + 8·6 = 50 (barcodes) bytes.
        frame(&self.payload()).unwrap_or_default()
    }

    /// Decodes a packet payload.
    pub fn decode(p: &[u8]) -> Result<Packet, CodecError> {
        let t = *p.first().ok_or(CodecError::Short {
            what: "packet",
            len: 0,
        })?;
        let u16_at = |i: usize| u16::from_le_bytes([p[i], p[i + 1]]);
        match t {
            0..=2 if p.len() == 1 => Ok(Packet::Sync(t)),
            0x32 | 0x33 => {
                if p.len() < 15 {
                    return Err(CodecError::Short {
                        what: "status",
                        len: p.len(),
                    });
                }
                let n = usize::from(p[14]);
                if p.len() < 15 + 3 * n || n > 24 {
                    return Err(CodecError::Short {
                        what: "status sonars",
                        len: p.len(),
                    });
                }
                Ok(Packet::Status(Status {
                    moving: t == 0x32,
                    x: u16_at(1) & 0x7fff,
                    y: u16_at(3) & 0x7fff,
                    th: u16_at(5) & 0x0fff,
                    vel: u16_at(7) as i16,
                    rvel: u16_at(9) as i16,
                    battery: p[11],
                    flags: u16_at(12),
                    sonars: (0..n)
                        .map(|i| (p[15 + 3 * i], u16_at(16 + 3 * i)))
                        .collect(),
                }))
            }
            0x40 => {
                let n = usize::from(*p.get(1).ok_or(CodecError::Short {
                    what: "barcodes",
                    len: p.len(),
                })?);
                if p.len() < 2 + 6 * n || n > MAX_SIGHTINGS {
                    return Err(CodecError::Short {
                        what: "barcodes",
                        len: p.len(),
                    });
                }
                Ok(Packet::Barcodes(
                    (0..n)
                        .map(|i| Sighting {
                            id: u16_at(2 + 6 * i),
                            bearing: u16_at(4 + 6 * i) as i16,
                            range: u16_at(6 + 6 * i),
                        })
                        .collect(),
                ))
            }
            0x50 if p.len() >= 5 => Ok(Packet::Stepped(u32::from_le_bytes([
                p[1], p[2], p[3], p[4],
            ]))),
            0x50 => Err(CodecError::Short {
                what: "stepped",
                len: p.len(),
            }),
            0x60 if p.len() >= 5 => Ok(Packet::Arm {
                strokes: u16_at(1),
                pressed: u16_at(3),
            }),
            0x61 if p.len() >= 3 => Ok(Packet::Said(u16_at(1))),
            0x60 | 0x61 => Err(CodecError::Short {
                what: "arm or said",
                len: p.len(),
            }),
            code => Err(CodecError::Unknown {
                what: "packet type",
                code,
            }),
        }
    }
}

/// Unwraps a 15-bit wrapping coordinate: the signed step from `prev` to `now`.
pub fn wrap_delta(prev: u16, now: u16) -> i32 {
    let d = (i32::from(now) - i32::from(prev)).rem_euclid(32768);
    if d >= 16384 { d - 32768 } else { d }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn checksum_matches_the_p2os_rule() {
        // SYNC0 as P2OS sends it: FA FB 03 00 00 00
        assert_eq!(
            frame(&[0]).unwrap(),
            vec![0xFA, 0xFB, 0x03, 0x00, 0x00, 0x00]
        );
        // ENABLE 1: payload 04 3B 01 00 -> 0x043B + 0x0100 = 0x053B
        assert_eq!(
            Command::Enable(true).encode(),
            vec![0xFA, 0xFB, 0x06, 0x04, 0x3B, 0x01, 0x00, 0x05, 0x3B]
        );
        // odd length: last byte XORed in
        assert_eq!(checksum(&[0x12, 0x34, 0x56]), 0x1234 ^ 0x56);
    }

    #[test]
    fn negative_arguments_use_their_own_type() {
        let p = Command::Vel(-300).payload();
        assert_eq!(p, vec![11, 0x1B, 0x2C, 0x01]);
        assert_eq!(Command::decode(&p).unwrap(), Command::Vel(-300));
    }

    #[test]
    fn the_decoder_resyncs_after_garbage_and_bad_frames() {
        let good = Packet::Sync(1).encode();
        let mut bad = Packet::Sync(2).encode();
        bad[3] ^= 0xFF; // corrupt the payload
        let mut stream = vec![0x00, 0x13, 0xFA, 0x77];
        stream.extend_from_slice(&bad);
        stream.extend_from_slice(&[0xFA, 0xFB, 0xFF]); // oversize COUNT
        stream.extend_from_slice(&good);
        let mut d = Decoder::default();
        d.push(&stream);
        let mut out = Vec::new();
        while let Some(f) = d.next_frame() {
            out.push(f);
        }
        assert!(matches!(out[0], Err(CodecError::BadChecksum { .. })));
        assert!(matches!(out[1], Err(CodecError::BadCount { count: 0xFF })));
        assert_eq!(out[2], Ok(vec![1]));
        assert_eq!(out.len(), 3);
        assert_eq!(d.stats.frames, 1);
        assert_eq!(d.stats.bad_checksum, 1);
        assert_eq!(d.stats.bad_count, 1);
        assert!(d.stats.garbage >= 4);
    }

    #[test]
    fn frames_split_anywhere_still_decode() {
        let bytes = Packet::Barcodes(vec![Sighting {
            id: 7,
            bearing: -450,
            range: 2500,
        }])
        .encode();
        for cut in 0..bytes.len() {
            let mut d = Decoder::default();
            d.push(&bytes[..cut]);
            assert!(d.next_frame().is_none());
            d.push(&bytes[cut..]);
            let p = d.next_frame().unwrap().unwrap();
            assert!(
                matches!(Packet::decode(&p).unwrap(), Packet::Barcodes(b) if b[0].bearing == -450)
            );
        }
    }

    #[test]
    fn unwrapping_handles_the_15_bit_rollover() {
        assert_eq!(wrap_delta(32760, 5), 13);
        assert_eq!(wrap_delta(5, 32760), -13);
        assert_eq!(wrap_delta(100, 200), 100);
    }

    fn status() -> impl Strategy<Value = Status> {
        (
            any::<bool>(),
            0u16..32768,
            0u16..32768,
            0u16..4096,
            any::<i16>(),
            any::<i16>(),
            any::<u8>(),
            any::<u16>(),
            proptest::collection::vec((0u8..24, any::<u16>()), 0..24),
        )
            .prop_map(
                |(moving, x, y, th, vel, rvel, battery, flags, sonars)| Status {
                    moving,
                    x,
                    y,
                    th,
                    vel,
                    rvel,
                    battery,
                    flags,
                    sonars,
                },
            )
    }

    proptest! {
        #[test]
        fn status_round_trips(s in status()) {
            let mut d = Decoder::default();
            d.push(&Packet::Status(s.clone()).encode());
            let p = d.next_frame().unwrap().unwrap();
            prop_assert_eq!(Packet::decode(&p).unwrap(), Packet::Status(s));
        }

        #[test]
        fn commands_round_trip(v in any::<i16>(), ms in any::<u16>(), on in any::<bool>(), text in "\\PC{0,80}") {
            for c in [Command::Vel(v), Command::RVel(v), Command::Period(ms), Command::Watchdog(ms), Command::Enable(on), Command::Sync0, Command::Step(ms), Command::Push, Command::Say(Text::new(&text))] {
                let mut d = Decoder::default();
                d.push(&c.encode());
                prop_assert_eq!(Command::decode(&d.next_frame().unwrap().unwrap()).unwrap(), c);
            }
        }

        #[test]
        fn arm_and_said_round_trip(strokes in any::<u16>(), pressed in any::<u16>()) {
            for p in [Packet::Arm { strokes, pressed }, Packet::Said(strokes)] {
                let mut d = Decoder::default();
                d.push(&p.encode());
                prop_assert_eq!(Packet::decode(&d.next_frame().unwrap().unwrap()).unwrap(), p);
            }
        }

        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let mut d = Decoder::default();
            d.push(&bytes);
            while let Some(f) = d.next_frame() {
                if let Ok(p) = f {
                    let _ = Packet::decode(&p);
                    let _ = Command::decode(&p);
                }
            }
        }

        #[test]
        fn a_valid_frame_survives_leading_garbage(garbage in proptest::collection::vec(any::<u8>(), 0..64)) {
            let mut d = Decoder::default();
            d.push(&garbage);
            d.push(&Packet::Sync(2).encode());
            // A fake header at the end of the garbage holds the frame until the line goes on
            // (its COUNT must be filled before its checksum can fail): the stream continues.
            d.push(&[0u8; MAX_COUNT + 3]);
            let mut got = false;
            while let Some(f) = d.next_frame() {
                if f == Ok(vec![2]) {
                    got = true;
                }
            }
            prop_assert!(got);
        }
    }
}
