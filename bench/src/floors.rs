//! The floors: a token passed through the cycle's topology with nothing else done.
//!
//! - [`Shape::Ring`] of depth D: the driver (this process) wakes node 1, which wakes node 2,
//!   …, node D wakes the driver, like a sync chain of depth D started by the manager.
//! - [`Shape::Star`] of N: the driver wakes N nodes, each wakes the driver back: the fan-out
//!   of N independent skills.
//!
//! Each round is timed as the fabric's cycle is ([`Timing`]): the driver stamps the start on
//! `CLOCK_MONOTONIC`, every node stamps the moment it passes the token on, and the round's
//! latency is the last node's stamp − the start: D wake-ups for a ring of depth D (one for a
//! star), the hops of a sync chain of depth D from its cycle start to its last run's end.
//! The round trip back to the driver (one wake-up more) is kept beside it, as the fabric's
//! is (cycle start → the manager handling the completion).
//!
//! Each is measured three ways: raw iceoryx2 (publish a sample, then notify the next node's
//! listener: the transport floor — the same services and settings the fabric uses), pipes
//! between processes (the OS floor: one `write` wakes one blocked `read`), and threads in one
//! process (no IPC: one channel send wakes one blocked thread). Nodes are `ring-node`
//! processes of this package.

use crate::PACE;
use skillfab_msgs::Tick;
use skillfab_proto::domain::Domain;
use skillfab_proto::header::now_ns;
use skillfab_proto::services;
use skillfab_tests::TestDomain;
use std::io::{Read, Write};
use std::process::{Child, Stdio};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::time::{Duration, Instant};

/// A topology.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// Driver → 1 → … → D → driver.
    Ring(usize),
    /// Driver → each of N → driver.
    Star(usize),
}

/// How the token travels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// iceoryx2 publish-subscribe + event, between processes.
    Iceoryx2,
    /// Pipes between processes.
    Pipe,
    /// Channels between threads of one process.
    Threads,
    /// `FUTEX_WAIT`/`FUTEX_WAKE` on shared memory between processes: the least a
    /// cross-process wake-up costs ([`crate::futex`]).
    Futex,
}

impl Transport {
    /// Its key in reports.
    pub fn key(&self) -> &'static str {
        match self {
            Transport::Iceoryx2 => "iceoryx2_ring",
            Transport::Pipe => "pipe_ring",
            Transport::Threads => "threads",
            Transport::Futex => "futex_ring",
        }
    }
}

/// Name of node `i`'s wake-up event (0: the driver).
pub fn event_name(i: usize) -> String {
    format!("bench/node/{i}")
}

/// Name of node `i`'s topic (0: the driver's).
pub fn topic_name(i: usize) -> String {
    format!("bench_node_{i}")
}

/// Sleeps until `next` (absolute), then moves it one `period` on.
fn pace(next: &mut Instant, period: Duration) {
    let now = Instant::now();
    if *next > now {
        std::thread::sleep(*next - now);
    }
    *next += period;
}

/// One round of a floor, timed as the fabric's cycle is (µs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// Driver's start stamp → the last node's stamp: the wake-ups of a chain of the same
    /// depth (the fabric's cycle latency).
    pub hops_us: f64,
    /// Driver's start stamp → the driver woken by the last node: one wake-up more.
    pub round_trip_us: f64,
}

impl Timing {
    pub(crate) fn from_ns(start: u64, last_stamp: u64, back: u64) -> Timing {
        let us = |ns: u64| ns as f64 / 1000.0;
        Timing {
            hops_us: us(last_stamp.saturating_sub(start)),
            round_trip_us: us(back.saturating_sub(start)),
        }
    }
}

/// The hop latencies of `rounds` (µs).
pub fn hops(rounds: &[Timing]) -> Vec<f64> {
    rounds.iter().map(|t| t.hops_us).collect()
}

/// `n` rounds of `round` (given the round's sequence number) after 10 unmeasured ones, back
/// to back or paced at [`PACE`].
pub(crate) fn rounds(n: usize, paced: bool, round: impl FnMut(u64) -> Timing) -> Vec<Timing> {
    rounds_every(n, paced.then_some(PACE), round)
}

/// As [`rounds`], one round every `period` (`None`: back to back).
pub(crate) fn rounds_every(
    n: usize,
    period: Option<Duration>,
    mut round: impl FnMut(u64) -> Timing,
) -> Vec<Timing> {
    for seq in 0..10 {
        round(seq);
    }
    let mut next = Instant::now();
    (0..n as u64)
        .map(|seq| {
            if let Some(p) = period {
                pace(&mut next, p);
            }
            round(seq)
        })
        .collect()
}

/// `n` rounds of a token through `shape` by `transport`, back to back or paced.
pub fn measure(shape: Shape, transport: Transport, paced: bool, n: usize) -> Vec<Timing> {
    match transport {
        Transport::Iceoryx2 => Iox::start(shape).rounds(n, paced),
        Transport::Pipe => Pipes::start(shape).rounds(n, paced),
        Transport::Threads => Threads::start(shape).rounds(n, paced),
        Transport::Futex => crate::futex::Futex::start(shape).rounds(n, paced),
    }
}

/// A running iceoryx2 ring or star.
pub struct Iox {
    shape: Shape,
    _node: iceoryx2::node::Node<iceoryx2::service::ipc::Service>,
    out: Vec<(
        iceoryx2::port::publisher::Publisher<
            iceoryx2::service::ipc::Service,
            Tick,
            skillfab_proto::header::SampleHeader,
        >,
        iceoryx2::port::notifier::Notifier<iceoryx2::service::ipc::Service>,
    )>,
    inbox: Vec<
        iceoryx2::port::subscriber::Subscriber<
            iceoryx2::service::ipc::Service,
            Tick,
            skillfab_proto::header::SampleHeader,
        >,
    >,
    listener: iceoryx2::port::listener::Listener<iceoryx2::service::ipc::Service>,
    seq: u64,
    /// Spin (poll the samples) this long before blocking on the listener.
    spin: Duration,
    // Last: its drop kills the nodes and removes the domain's files after the ports went.
    _t: TestDomain,
}

impl Iox {
    /// Starts the nodes and waits until each is ready.
    pub fn start(shape: Shape) -> Iox {
        Iox::start_spinning(shape, Duration::ZERO)
    }

    /// [`Iox::start`] with every participant polling for its sample for up to `spin` before
    /// it blocks (the spin-then-block strategy).
    pub fn start_spinning(shape: Shape, spin: Duration) -> Iox {
        let mut t = TestDomain::new("iox");
        let node = services::node(&t.domain, "bench-driver").unwrap();
        let listener = services::listener(&node, &event_name(0)).unwrap();
        let ready = services::listener(&node, "bench/ready").unwrap();
        let (count, next_of): (usize, Box<dyn Fn(usize) -> usize>) = match shape {
            Shape::Ring(d) => (d, Box::new(move |i| (i + 1) % (d + 1))),
            Shape::Star(n) => (n, Box::new(|_| 0)),
        };
        // Each star node answers on its own topic; a ring's last node on topic 0.
        let mut inbox = Vec::new();
        match shape {
            Shape::Ring(_) => {
                inbox.push(services::subscriber::<Tick>(&node, &topic_name(0)).unwrap())
            }
            Shape::Star(n) => {
                for i in 1..=n {
                    inbox.push(
                        services::subscriber::<Tick>(&node, &format!("bench_back_{i}")).unwrap(),
                    );
                }
            }
        }
        for i in 1..=count {
            let next = next_of(i);
            let out_topic = match shape {
                Shape::Ring(_) => topic_name(next),
                Shape::Star(_) => format!("bench_back_{i}"),
            };
            t.spawn(
                "ring-node",
                &[
                    "iox",
                    &i.to_string(),
                    &topic_name(i),
                    &event_name(i),
                    &out_topic,
                    &event_name(next),
                    &spin.as_micros().to_string(),
                ],
            );
        }
        let out = match shape {
            Shape::Ring(_) => vec![(
                services::publisher::<Tick>(&node, &topic_name(1)).unwrap(),
                services::notifier(&node, &event_name(1)).unwrap(),
            )],
            Shape::Star(n) => (1..=n)
                .map(|i| {
                    (
                        services::publisher::<Tick>(&node, &topic_name(i)).unwrap(),
                        services::notifier(&node, &event_name(i)).unwrap(),
                    )
                })
                .collect(),
        };
        // Every node says it is ready (its listener exists) with its own event id.
        let mut seen = std::collections::HashSet::new();
        let deadline = Instant::now() + skillfab_tests::WAIT;
        while seen.len() < count {
            assert!(Instant::now() < deadline, "ring nodes not ready: {seen:?}");
            ready
                .timed_wait(
                    |a| {
                        seen.insert(a.id.as_value());
                    },
                    Duration::from_millis(100),
                )
                .unwrap();
        }
        Iox {
            shape,
            _node: node,
            out,
            inbox,
            listener,
            seq: 0,
            spin,
            _t: t,
        }
    }

    fn round(&mut self) -> Timing {
        self.seq += 1;
        let start = now_ns();
        for (p, n) in &self.out {
            let s = p.loan_uninit().unwrap();
            let mut s = s.write_payload(Tick { value: self.seq });
            s.user_header_mut().cycle = self.seq;
            s.user_header_mut().stamp_ns = start;
            s.send().unwrap();
            n.notify().unwrap();
        }
        let want = match self.shape {
            Shape::Ring(_) => 1,
            Shape::Star(n) => n,
        };
        let mut got = 0;
        let mut last_stamp = 0;
        let spin_until = Instant::now() + self.spin;
        while got < want {
            if Instant::now() >= spin_until {
                self.listener.blocking_wait(|_| {}).unwrap();
            } else {
                std::hint::spin_loop();
            }
            for sub in &self.inbox {
                while let Some(s) = sub.receive().unwrap() {
                    if s.payload().value == self.seq {
                        got += 1;
                        last_stamp = last_stamp.max(s.user_header().stamp_ns);
                    }
                }
            }
        }
        Timing::from_ns(start, last_stamp, now_ns())
    }

    /// Process ids of the nodes.
    pub fn node_pids(&self) -> Vec<u32> {
        let n = match self.shape {
            Shape::Ring(d) => d,
            Shape::Star(n) => n,
        };
        (0..n).map(|i| self._t.pid(i)).collect()
    }

    /// `n` rounds.
    pub fn rounds(&mut self, n: usize, paced: bool) -> Vec<Timing> {
        rounds(n, paced, |_| self.round())
    }
}

/// A running pipe ring or star.
pub struct Pipes {
    _t: TestDomain,
    children: Vec<Child>,
    /// Where the driver writes (one per star node; the ring's first node).
    to: Vec<std::process::ChildStdin>,
    /// Where the driver reads (one per star node; the ring's last node).
    from: Vec<std::process::ChildStdout>,
}

impl Pipes {
    /// Starts the nodes, their stdin/stdout chained.
    pub fn start(shape: Shape) -> Pipes {
        let t = TestDomain::new("pipe");
        let spawn = |stdin: Stdio| {
            t.command("ring-node")
                .arg("pipe")
                .stdin(stdin)
                .stdout(Stdio::piped())
                .spawn()
                .unwrap()
        };
        let mut children = Vec::new();
        let (mut to, mut from) = (Vec::new(), Vec::new());
        match shape {
            Shape::Ring(d) => {
                let mut first = spawn(Stdio::piped());
                to.push(first.stdin.take().unwrap());
                let mut prev_out = first.stdout.take().unwrap();
                children.push(first);
                for _ in 1..d {
                    let mut c = spawn(Stdio::from(prev_out));
                    prev_out = c.stdout.take().unwrap();
                    children.push(c);
                }
                from.push(prev_out);
            }
            Shape::Star(n) => {
                for _ in 0..n {
                    let mut c = spawn(Stdio::piped());
                    to.push(c.stdin.take().unwrap());
                    from.push(c.stdout.take().unwrap());
                    children.push(c);
                }
            }
        }
        Pipes {
            _t: t,
            children,
            to,
            from,
        }
    }

    fn round(&mut self) -> Timing {
        let start = now_ns();
        for w in &mut self.to {
            w.write_all(&start.to_ne_bytes()).unwrap();
        }
        let mut last_stamp = 0;
        let mut b = [0u8; 8];
        for r in &mut self.from {
            r.read_exact(&mut b).unwrap();
            last_stamp = last_stamp.max(u64::from_ne_bytes(b));
        }
        Timing::from_ns(start, last_stamp, now_ns())
    }

    /// `n` rounds.
    pub fn rounds(&mut self, n: usize, paced: bool) -> Vec<Timing> {
        rounds(n, paced, |_| self.round())
    }
}

impl Drop for Pipes {
    fn drop(&mut self) {
        // Closing stdin ends each node (EOF), which closes the next one's.
        self.to.clear();
        for c in &mut self.children {
            let _ = c.wait();
        }
    }
}

/// A running thread ring or star.
pub struct Threads {
    to: Vec<SyncSender<u64>>,
    from: Receiver<u64>,
    want: usize,
}

impl Threads {
    /// Starts the threads, chained by bounded channels.
    pub fn start(shape: Shape) -> Threads {
        let (back_tx, from) = sync_channel::<u64>(64);
        // Each relay passes on the moment it passes the token on.
        let relay = |rx: Receiver<u64>, tx: SyncSender<u64>| {
            std::thread::spawn(move || {
                while rx.recv().is_ok() {
                    if tx.send(now_ns()).is_err() {
                        break;
                    }
                }
            });
        };
        let mut to = Vec::new();
        let want = match shape {
            Shape::Ring(d) => {
                let (first_tx, mut rx) = sync_channel::<u64>(1);
                to.push(first_tx);
                for _ in 1..d {
                    let (tx, next_rx) = sync_channel::<u64>(1);
                    relay(rx, tx);
                    rx = next_rx;
                }
                relay(rx, back_tx);
                1
            }
            Shape::Star(n) => {
                for _ in 0..n {
                    let (tx, rx) = sync_channel::<u64>(1);
                    to.push(tx);
                    relay(rx, back_tx.clone());
                }
                n
            }
        };
        Threads { to, from, want }
    }

    fn round(&mut self, seq: u64) -> Timing {
        let start = now_ns();
        for tx in &self.to {
            tx.send(seq).unwrap();
        }
        let mut last_stamp = 0;
        for _ in 0..self.want {
            last_stamp = last_stamp.max(self.from.recv().unwrap());
        }
        Timing::from_ns(start, last_stamp, now_ns())
    }

    /// `n` rounds.
    pub fn rounds(&mut self, n: usize, paced: bool) -> Vec<Timing> {
        rounds(n, paced, |seq| self.round(seq))
    }
}

/// Node `index` of an iceoryx2 ring or star (the `ring-node iox` process): wakes on its
/// event, takes its topic's sample, publishes it on `out_topic` and notifies `out_event`.
pub fn iox_node(
    domain: &Domain,
    index: usize,
    topic: &str,
    event: &str,
    out_topic: &str,
    out_event: &str,
    spin: Duration,
) {
    let node = services::node(domain, &format!("bench-node-{index}")).unwrap();
    let sub = services::subscriber::<Tick>(&node, topic).unwrap();
    let listener = services::listener(&node, event).unwrap();
    let publisher = services::publisher::<Tick>(&node, out_topic).unwrap();
    let notifier = services::notifier(&node, out_event).unwrap();
    let ready = services::notifier(&node, "bench/ready").unwrap();
    ready
        .notify_with_custom_event_id(iceoryx2::prelude::EventId::new(index))
        .unwrap();
    // Ends on SIGTERM (the fixture's clean-up): the wait then fails.
    let mut last = Instant::now();
    loop {
        // Poll for up to `spin` after the last sample, then block.
        if last.elapsed() >= spin {
            if listener.blocking_wait(|_| {}).is_err() {
                break;
            }
        } else {
            std::hint::spin_loop();
            let _ = listener.try_wait(|_| {});
        }
        while let Some(s) = sub.receive().unwrap() {
            last = Instant::now();
            let mut out = publisher.loan_uninit().unwrap().write_payload(*s.payload());
            *out.user_header_mut() = *s.user_header();
            // The moment this node passes the token on (the driver keeps the last one's).
            out.user_header_mut().stamp_ns = now_ns();
            out.send().unwrap();
            notifier.notify().unwrap();
        }
    }
}

/// A pipe node (the `ring-node pipe` process): for each 8-byte token on stdin, writes the
/// moment it passes it on (`CLOCK_MONOTONIC` ns, 8 bytes) to stdout, until EOF.
pub fn pipe_node() {
    let mut b = [0u8; 8];
    let (mut i, mut o) = (std::io::stdin().lock(), std::io::stdout().lock());
    while i.read_exact(&mut b).is_ok() {
        let stamp = now_ns().to_ne_bytes();
        if o.write_all(&stamp).and_then(|()| o.flush()).is_err() {
            break;
        }
    }
}
