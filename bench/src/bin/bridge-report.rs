//! `bridge-report`: what the Zenoh bridge costs, against raw Zenoh in the same run.
//!
//! ```text
//! bridge-report [--rounds N] [--pings P] [--flood-s S] [--json]
//! ```
//!
//! Two domains on this host, A and B, each with its manager, joined by two bridges over
//! TCP on 127.0.0.1 (Zenoh peers). In A a sync source (`blob-src-64` or `blob-src-1M`) writes
//! its cycle number into a `ping` of 64 B or 1 MiB; A's bridge exports it; B's bridge imports
//! it; in B an async skill (`bridge-echo`) copies it to `pong`; B's bridge exports `pong`; A's
//! bridge republishes it in A. A's manager is stepped one cycle per ping.
//!
//! - **Round trip** (per payload): `ping` sent in A (its sample stamp) → `pong` of the same
//!   sequence number seen by an observer in A: 4 shared-memory hops, 2 TCP hops, 4 processes
//!   on the way (2 bridges, the echo skill, the observer's wake-up). Baseline: a raw Zenoh
//!   put → subscriber → put back → subscriber between this process and `zenoh-pong` (2 TCP
//!   hops, 2 processes), same payload, same run.
//! - **Throughput** (1 MiB): A's manager free-running, the 1 MiB source publishing every
//!   cycle (B's echo inactive: one way); B's bridge's count of samples republished in B over
//!   S seconds (default 5).
//!   Baseline: this process putting 1 MiB payloads to `zenoh-pong` for S seconds; its count.
//!
//! Rounds (default 5) interleave the bridge and the baseline, alternating which goes first.
//! Release binaries beside this one (`cargo build --release --workspace --bins`).

// A report tool: a failed set-up step ends it with its message.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use serde_json::json;
use skill_sdk::prelude::Message;
use skillfab_bridge::ZenohOptions;
use skillfab_client::Client;
use skillfab_proto::header::now_ns;
use skillfab_proto::names;
use skillfab_proto::services::{self, RawReader};
use skillfab_tests::TestDomain;
use skillfab_tests::skills::{Blob1M, Blob64};
use std::sync::mpsc::{Receiver, sync_channel};
use std::time::{Duration, Instant};
use zenoh::Wait;

fn arg<T: std::str::FromStr>(args: &[String], name: &str, default: T) -> T {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// One payload size: its name, bytes, source program and topics.
#[derive(Clone, Copy)]
struct Size {
    name: &'static str,
    bytes: usize,
    src: &'static str,
}

const SIZES: [Size; 2] = [
    Size {
        name: "64",
        bytes: 64,
        src: "blob-src-64",
    },
    Size {
        name: "1M",
        bytes: 1 << 20,
        src: "blob-src-1M",
    },
];

/// The two bridged domains and the observer in A. Fields drop in order: the observer and
/// the clients before the domains' files go.
struct Bridged {
    /// Per size: (ping reader, pong reader, pong listener) in A.
    readers: Vec<(
        RawReader,
        RawReader,
        iceoryx2::port::listener::Listener<iceoryx2::prelude::ipc::Service>,
    )>,
    _node: iceoryx2::node::Node<iceoryx2::prelude::ipc::Service>,
    ca: Client,
    cb: Client,
    a: TestDomain,
    _b: TestDomain,
}

fn bridged() -> Bridged {
    let (mut a, mut b) = (TestDomain::new("bra"), TestDomain::new("brb"));
    a.spawn("skillfab", &["manager", "--free-run", "--paused"]);
    b.spawn("skillfab", &["manager", "--period-ms", "10"]);
    a.board();
    b.board();
    for s in SIZES {
        let (ping, pong) = (format!("ping{}", s.name), format!("pong{}", s.name));
        a.spawn(
            s.src,
            &[
                "--name",
                &format!("src{}", s.name),
                "--inactive",
                "--remap",
                &format!("blob={ping}"),
            ],
        );
        b.spawn(
            "bridge-echo",
            &[
                "--size",
                s.name,
                "--name",
                &format!("echo{}", s.name),
                "--remap",
                &format!("ping={ping}"),
                "--remap",
                &format!("pong={pong}"),
            ],
        );
    }
    let ca = Client::connect(&a.domain).unwrap();
    let cb = Client::connect(&b.domain).unwrap();
    a.wait_until("the sources", || ca.list().is_ok_and(|l| l.len() == 2));
    b.wait_until("the echoes", || cb.list().is_ok_and(|l| l.len() == 2));
    let listen = format!("tcp/127.0.0.1:{}", free_port());
    let (an, bn) = (a.domain.name().to_string(), b.domain.name().to_string());
    a.spawn(
        "skillfab",
        &[
            "bridge",
            "--listen",
            &listen,
            "--export",
            "ping64,ping1M",
            "--import",
            "pong64,pong1M",
            "--from",
            &bn,
        ],
    );
    b.spawn(
        "skillfab",
        &[
            "bridge",
            "--connect",
            &listen,
            "--import",
            "ping64,ping1M",
            "--export",
            "pong64,pong1M",
            "--from",
            &an,
        ],
    );
    a.wait_until("A's bridge", || ca.list().is_ok_and(|l| l.len() == 3));
    b.wait_until("B's bridge", || cb.list().is_ok_and(|l| l.len() == 3));
    let node = services::node(&a.domain, "observer").unwrap();
    let readers = SIZES
        .iter()
        .map(|s| {
            let schema = if s.bytes == 64 {
                Blob64::schema()
            } else {
                Blob1M::schema()
            };
            let (ping, pong) = (format!("ping{}", s.name), format!("pong{}", s.name));
            (
                RawReader::open(&node, &ping, &schema).unwrap(),
                RawReader::open(&node, &pong, &schema).unwrap(),
                services::listener(&node, &names::topic(&pong)).unwrap(),
            )
        })
        .collect();
    Bridged {
        a,
        _b: b,
        ca,
        cb,
        readers,
        _node: node,
    }
}

/// The sequence number at the start of a blob.
fn seq(bytes: &[u8]) -> u64 {
    u64::from_le_bytes(bytes[..8].try_into().unwrap())
}

impl Bridged {
    /// `pings` round trips of size `i` through the bridges (µs); lost ones are left out and
    /// counted.
    fn round_trips(&mut self, i: usize, pings: usize) -> (Vec<f64>, usize) {
        let s = SIZES[i];
        self.ca.activate(&[&format!("src{}", s.name)]).unwrap();
        let (mut out, mut lost) = (Vec::new(), 0);
        for _ in 0..pings {
            let k = self.ca.step(1).unwrap();
            let (ping, pong, listener) = &mut self.readers[i];
            let mut sent = None;
            let mut back = None;
            let deadline = Instant::now() + Duration::from_secs(2);
            while back.is_none() && Instant::now() < deadline {
                let _ = listener.timed_wait(|_| {}, Duration::from_millis(100));
                let now = now_ns();
                pong.drain(&mut |b, _| {
                    if seq(b) == k {
                        back = Some(now);
                    }
                })
                .unwrap();
            }
            ping.drain(&mut |b, h| {
                if seq(b) == k {
                    sent = Some(h.stamp_ns);
                }
            })
            .unwrap();
            match (sent, back) {
                (Some(t0), Some(t1)) => out.push(t1.saturating_sub(t0) as f64 / 1000.0),
                _ => lost += 1,
            }
        }
        self.ca.deactivate(&[&format!("src{}", s.name)]).unwrap();
        (out, lost)
    }

    /// 1 MiB samples republished in B per second, A's source free-running for `secs`.
    fn throughput(&mut self, secs: f64) -> f64 {
        // One way only, as the baseline: B does not echo while A floods.
        self.cb.deactivate(&["echo1M"]).unwrap();
        self.ca.activate(&["src1M"]).unwrap();
        self.ca.run().unwrap();
        let imported = |c: &Client| {
            c.stats().ok().and_then(|s| {
                s.bridges.first().and_then(|b| {
                    b.imports
                        .iter()
                        .find(|t| t.topic == "ping1M")
                        .map(|t| t.samples)
                })
            })
        };
        // Reports come once a second: read the count right after it changes, at the start and
        // at the end of the window.
        let changed = |c: &Client, from: Option<u64>| loop {
            let n = imported(c);
            if n != from {
                return (Instant::now(), n.unwrap_or(0));
            }
            std::thread::sleep(Duration::from_millis(10));
        };
        let first = imported(&self.cb);
        let (t1, n1) = changed(&self.cb, first);
        std::thread::sleep(Duration::from_secs_f64(secs - 0.5));
        let mid = imported(&self.cb);
        let (t2, n2) = changed(&self.cb, mid);
        self.ca.stop().unwrap();
        self.ca.deactivate(&["src1M"]).unwrap();
        self.cb.activate(&["echo1M"]).unwrap();
        (n2 - n1) as f64 / (t2 - t1).as_secs_f64()
    }
}

/// Raw Zenoh between this process and `zenoh-pong`.
struct Raw {
    _session: zenoh::Session,
    ping: zenoh::pubsub::Publisher<'static>,
    flood: zenoh::pubsub::Publisher<'static>,
    done: zenoh::pubsub::Publisher<'static>,
    pongs: Receiver<Vec<u8>>,
    counts: Receiver<u64>,
    _subs: Vec<zenoh::pubsub::Subscriber<()>>,
}

fn raw(t: &mut TestDomain) -> Raw {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    t.spawn("zenoh-pong", &["--listen", &endpoint]);
    let session = skillfab_bridge::link::open(&ZenohOptions {
        connect: vec![endpoint],
        ..Default::default()
    })
    .unwrap();
    let publisher = |key: &'static str| {
        session
            .declare_publisher(key)
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .express(true)
            .wait()
            .unwrap()
    };
    let (ping, flood, done) = (
        publisher("raw/ping"),
        publisher("raw/flood"),
        publisher("raw/done"),
    );
    let (tx, pongs) = sync_channel(16);
    let (ctx, counts) = sync_channel(16);
    let subs = vec![
        session
            .declare_subscriber("raw/pong")
            .callback(move |s| {
                let _ = tx.send(s.payload().to_bytes().into_owned());
            })
            .wait()
            .unwrap(),
        session
            .declare_subscriber("raw/counted")
            .callback(move |s| {
                let b = s.payload().to_bytes();
                let _ = ctx.send(u64::from_le_bytes(b[..8].try_into().unwrap_or([0; 8])));
            })
            .wait()
            .unwrap(),
    ];
    let r = Raw {
        _session: session,
        ping,
        flood,
        done,
        pongs,
        counts,
        _subs: subs,
    };
    // The ponger is there once a ping comes back.
    let deadline = Instant::now() + Duration::from_secs(30);
    while r.round_trip(64, 0).is_none() {
        assert!(Instant::now() < deadline, "zenoh-pong does not answer");
    }
    r
}

impl Raw {
    fn round_trip(&self, bytes: usize, k: u64) -> Option<f64> {
        let mut payload = vec![0u8; bytes];
        payload[..8].copy_from_slice(&k.to_le_bytes());
        let t0 = now_ns();
        self.ping.put(payload).wait().unwrap();
        let deadline = Instant::now() + Duration::from_secs(2);
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.pongs.recv_timeout(left) {
                Ok(b) if seq(&b) == k => return Some(now_ns().saturating_sub(t0) as f64 / 1000.0),
                Ok(_) => {}
                Err(_) => return None,
            }
        }
        None
    }

    fn round_trips(&self, bytes: usize, pings: usize) -> (Vec<f64>, usize) {
        let (mut out, mut lost) = (Vec::new(), 0);
        for k in 1..=pings as u64 {
            match self.round_trip(bytes, k) {
                Some(us) => out.push(us),
                None => lost += 1,
            }
        }
        (out, lost)
    }

    /// 1 MiB payloads received by `zenoh-pong` per second over `secs`.
    fn throughput(&self, secs: f64) -> f64 {
        let payload = vec![7u8; 1 << 20];
        let t0 = Instant::now();
        while t0.elapsed().as_secs_f64() < secs {
            self.flood.put(payload.clone()).wait().unwrap();
        }
        self.done.put(vec![0u8]).wait().unwrap();
        let n = self.counts.recv_timeout(Duration::from_secs(30)).unwrap();
        n as f64 / t0.elapsed().as_secs_f64()
    }
}

fn summary(v: &[f64]) -> serde_json::Value {
    if v.is_empty() {
        return json!(null);
    }
    let s = skillfab_bench::Summary::of(v);
    json!({"p50_us": s.p50, "p99_us": s.p99, "max_us": s.max, "n": v.len()})
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rounds: usize = arg(&args, "--rounds", 5);
    let pings: usize = arg(&args, "--pings", 200);
    let secs: f64 = arg(&args, "--flood-s", 5.0);
    let as_json = args.iter().any(|a| a == "--json");
    let mut fabric = bridged();
    let raw = raw(&mut fabric.a);
    let mut rtt: Vec<[(Vec<f64>, usize); 2]> = SIZES.iter().map(|_| Default::default()).collect();
    let mut tput: [Vec<f64>; 2] = Default::default();
    for round in 0..rounds {
        let order = if round % 2 == 0 { [0, 1] } else { [1, 0] };
        for (i, s) in SIZES.iter().enumerate() {
            for which in order {
                let (v, lost) = match which {
                    0 => fabric.round_trips(i, pings),
                    _ => raw.round_trips(s.bytes, pings),
                };
                rtt[i][which].0.extend(v);
                rtt[i][which].1 += lost;
            }
        }
        for which in order {
            tput[which].push(match which {
                0 => fabric.throughput(secs),
                _ => raw.throughput(secs),
            });
        }
        eprintln!("round {} of {rounds} done", round + 1);
    }
    let median = |v: &[f64]| skillfab_bench::Summary::of(v).p50;
    let report = json!({
        "rounds": rounds, "pings_per_round": pings, "flood_s": secs,
        "round_trip": SIZES.iter().enumerate().map(|(i, s)| json!({
            "payload": s.name,
            "bridge": summary(&rtt[i][0].0), "bridge_lost": rtt[i][0].1,
            "raw_zenoh": summary(&rtt[i][1].0), "raw_zenoh_lost": rtt[i][1].1,
        })).collect::<Vec<_>>(),
        "throughput_1MiB_per_s": {
            "bridge": tput[0], "raw_zenoh": tput[1],
            "bridge_median": median(&tput[0]), "raw_zenoh_median": median(&tput[1]),
        },
    });
    if as_json {
        println!("{report}");
    } else {
        println!("{}", serde_json::to_string_pretty(&report).unwrap());
    }
}
