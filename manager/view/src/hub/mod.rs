//! The hub: the view's one thread on the fabric's side. It owns the control client and a
//! reader per topic — an external reader like any other, so the cycle never waits for it —
//! and fans what it reads out to the viewers' outboxes; it answers the viewers' requests.
//!
//! Channels, each advertised to every viewer:
//!
//! | topic | encoding | what |
//! |---|---|---|
//! | `/<topic>` | `cdr` (`ros2msg` schema) | every topic of the domain, each sample as published |
//! | `/tf` | `json` `foxglove.FrameTransforms` | `map → odom` (the start pose), `odom → base_link` (odometry), `map → truth` (the simulator's ground truth, with `--truth`) |
//! | `/scene` | `json` `foxglove.SceneUpdate` | the world's walls, doors, boxes, barcodes; a building's floors stacked, its cabins and call button (with `--world`) |
//! | `/robot` | `json` `foxglove.SceneUpdate` | the robot's body and its sonar ring as cones, in `base_link` |
//! | `/events` | `json` `foxglove.Log` | the manager's events |
//! | `/log` | `json` `foxglove.Log` | the skills' log lines |
//! | `/plan` | `json` `skillfab.PlanTree` | the running plan's tree with each node's status, on every change |
//!
//! What viewers ask (subscriptions, parameters, service calls) is answered in [`requests`].
//!
//! Parameters are `/<skill>/<param>` (get, set — checked by the manager as `ctl set` is —
//! and subscribed to); services `/skillfab/activate` and `/skillfab/deactivate` take
//! `{"skills": [...]}` in JSON.

mod requests;

use crate::conn::{Outbox, Wishes};
use crate::protocol::{self, Channel, ClientMessage, ServerMessage, ServiceCall};
use crate::scene::{self, Scene};
use requests::{parameter, services};
use serde_json::{Value as Json, json};
use skillfab_client::{Client, ClientError};
use skillfab_proto::bridge::unix_now_ns;
use skillfab_proto::control::{Event, EventKind, NodeStatus, PlanTree};
use skillfab_proto::domain::Domain;
use skillfab_proto::log::{Level as LogLevel, LogLine};
use skillfab_proto::schema::MessageSchema;
use skillfab_proto::services::{self, RawReader};
use skillfab_proto::value::{FieldPath, Value, resolve};
use skillfab_proto::{cdr, ros2msg};
use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, TryRecvError};
use std::time::{Duration, Instant};

/// A viewer's number, for the server's life.
pub type ViewerId = u64;

/// What a viewer's connection tells the hub.
pub enum FromViewer {
    /// A viewer completed its handshake.
    Joined {
        /// Its number.
        id: ViewerId,
        /// Where to queue what it is sent.
        outbox: Arc<Outbox>,
        /// What it asked for in its address.
        wishes: Wishes,
    },
    /// A request.
    Message {
        /// The viewer.
        id: ViewerId,
        /// The request.
        message: ClientMessage,
    },
    /// A service call.
    Call {
        /// The viewer.
        id: ViewerId,
        /// The call.
        call: ServiceCall,
    },
    /// The viewer left.
    Left {
        /// Its number.
        id: ViewerId,
    },
}

/// How long the hub waits for an event before it reads the topics again: samples reach
/// viewers at most this late.
const POLL: Duration = Duration::from_millis(5);
/// How often the hub looks for new topics.
const DISCOVER: Duration = Duration::from_secs(1);
/// How often the ground-truth file is read again.
const TRUTH: Duration = Duration::from_millis(100);
/// How often the static transform is sent again (for viewers that dropped it).
const STATIC_TF: Duration = Duration::from_secs(2);
/// How long a control request may take.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(2);

/// The service ids.
const ACTIVATE: u32 = 1;
const DEACTIVATE: u32 = 2;

/// The view's own channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Own {
    Tf,
    Scene,
    Robot,
    Events,
    Log,
    Plan,
}

/// What a channel carries.
enum Source {
    /// A fabric topic.
    Topic(Box<TopicReader>),
    Own(Own),
}

/// A fabric topic's message schema and reader.
struct TopicReader {
    schema: MessageSchema,
    reader: RawReader,
}

struct ChannelState {
    channel: Channel,
    source: Source,
}

struct Viewer {
    outbox: Arc<Outbox>,
    wishes: Wishes,
    /// Subscription id → channel id.
    subs: HashMap<u32, u32>,
    /// Channel id → (subscription ids, when last sent).
    by_channel: HashMap<u32, (Vec<u32>, Option<Instant>)>,
    /// Parameter names it follows (`None`: not subscribed; an empty set: all).
    params: Option<HashSet<String>>,
}

/// What the hub reads off the fabric's topics for its own channels.
struct Robot {
    sonar_topic: Option<String>,
    odom_topic: Option<String>,
    ranges: Option<FieldPath>,
    odom: Option<[FieldPath; 3]>,
}

/// The hub's options.
pub struct HubOptions {
    /// The domain.
    pub domain: Domain,
    /// The world shown (`--world`).
    pub scene: Option<Scene>,
    /// The simulator's ground truth file (`--truth`).
    pub truth: Option<PathBuf>,
    /// Every viewer's throttle unless it asks for its own (`--max-hz`).
    pub max_hz: Option<f64>,
}

/// The hub's state.
pub struct Hub {
    opts: HubOptions,
    client: Option<Client>,
    node: iceoryx2::node::Node<iceoryx2::service::ipc::Service>,
    channels: BTreeMap<u32, ChannelState>,
    by_topic: HashMap<String, u32>,
    own: HashMap<Own, u32>,
    next_channel: u32,
    viewers: HashMap<ViewerId, Viewer>,
    robot: Robot,
    plan: Option<PlanTree>,
    plan_cycle: u64,
    truth_len: u64,
    last_discover: Option<Instant>,
    last_truth: Instant,
    last_static: Instant,
}

fn stamp(ns: u64) -> Json {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

/// A JSON Schema for a channel of the view's own: enough for a reader to know it is an object
/// of that name (Foxglove's panels know the `foxglove.*` ones by name).
fn object_schema(title: &str) -> String {
    json!({"type": "object", "title": title}).to_string()
}

fn own_channel(own: Own, id: u32) -> Channel {
    let (topic, schema) = match own {
        Own::Tf => ("/tf", "foxglove.FrameTransforms"),
        Own::Scene => ("/scene", "foxglove.SceneUpdate"),
        Own::Robot => ("/robot", "foxglove.SceneUpdate"),
        Own::Events => ("/events", "foxglove.Log"),
        Own::Log => ("/log", "foxglove.Log"),
        Own::Plan => ("/plan", "skillfab.PlanTree"),
    };
    Channel {
        id,
        topic: topic.into(),
        encoding: "json".into(),
        schema_name: schema.into(),
        schema: object_schema(schema),
        schema_encoding: "jsonschema".into(),
    }
}

/// The plan tree as the `/plan` channel sends it: every node with its status and the cycle
/// it took it in, and the running branch from the root.
pub fn plan_json(tree: &PlanTree, cycle: u64) -> Json {
    let nodes: Vec<Json> = tree
        .nodes
        .iter()
        .map(|n| {
            let (status, since) = tree
                .status
                .get(n.id as usize)
                .copied()
                .unwrap_or((NodeStatus::Idle, 0));
            json!({"id": n.id, "parent": n.parent, "name": n.name, "kind": n.kind,
                   "detail": n.detail, "status": status.as_str(), "since_cycle": since})
        })
        .collect();
    json!({"plan": tree.plan, "cycle": cycle, "nodes": nodes,
           "running_branch": running_branch(tree).into_iter()
               .map(|(depth, node)| json!({"depth": depth, "node": node}))
               .collect::<Vec<_>>()})
}

/// Where the plan is: every node that is running or holds a running node below it, in tree
/// order, with its depth (a `Parallel` has several running children: each branch is there).
pub fn running_branch(tree: &PlanTree) -> Vec<(usize, String)> {
    let depths = tree.depths();
    tree.running_branch()
        .iter()
        .zip(&tree.nodes)
        .filter(|(on, _)| **on)
        .map(|(_, n)| {
            let label = if n.name.is_empty() || n.name == n.kind {
                n.kind.clone()
            } else {
                format!("{} {}", n.kind, n.name)
            };
            (depths.get(n.id as usize).copied().unwrap_or(0), label)
        })
        .collect()
}

/// The last complete record of a ground-truth file `len` bytes long, reading its header and
/// its last few kilobytes only (the file grows for the whole run).
fn last_truth_record(path: &std::path::Path, len: u64) -> Option<denning_sim::truth::TruthRecord> {
    use std::io::{BufRead, Read, Seek, SeekFrom};
    let mut f = std::io::BufReader::new(std::fs::File::open(path).ok()?);
    let mut header = String::new();
    f.read_line(&mut header).ok()?;
    let from = len.saturating_sub(4096).max(header.len() as u64);
    f.seek(SeekFrom::Start(from)).ok()?;
    let mut tail = String::new();
    f.take(len - from).read_to_string(&mut tail).ok()?;
    // The text after the last newline is a line being written.
    let complete = &tail[..tail.rfind('\n')?];
    let last = complete.rsplit('\n').next()?;
    denning_sim::truth::TruthRecord::parse_all(&format!("{}\n{last}\n", header.trim_end()))
        .into_iter()
        .next()
}

fn event_level(k: &EventKind) -> u8 {
    // foxglove.Log: 1 debug, 2 info, 3 warning, 4 error.
    match k {
        EventKind::SkillDied { .. } | EventKind::ProcessGaveUp { .. } => 4,
        EventKind::DeviceLost { .. } | EventKind::CycleOverrun { .. } => 3,
        _ => 2,
    }
}

fn log_level(l: LogLevel) -> u8 {
    match l {
        LogLevel::Trace | LogLevel::Debug => 1,
        LogLevel::Info => 2,
        LogLevel::Warn => 3,
        LogLevel::Error => 4,
    }
}

impl Hub {
    /// The hub of `opts.domain`; the manager may come later.
    fn new(opts: HubOptions) -> Result<Hub, skillfab_proto::Error> {
        let node = services::node(&opts.domain, &format!("view-{}", std::process::id()))?;
        let mut hub = Hub {
            opts,
            client: None,
            node,
            channels: BTreeMap::new(),
            by_topic: HashMap::new(),
            own: HashMap::new(),
            next_channel: 1,
            viewers: HashMap::new(),
            robot: Robot {
                sonar_topic: None,
                odom_topic: None,
                ranges: None,
                odom: None,
            },
            plan: None,
            plan_cycle: 0,
            truth_len: 0,
            last_discover: None,
            last_truth: Instant::now(),
            last_static: Instant::now(),
        };
        let mut own = vec![Own::Tf, Own::Robot, Own::Events, Own::Log, Own::Plan];
        if hub.opts.scene.is_some() {
            own.push(Own::Scene);
        }
        for o in own {
            let id = hub.take_channel_id();
            hub.own.insert(o, id);
            hub.channels.insert(
                id,
                ChannelState {
                    channel: own_channel(o, id),
                    source: Source::Own(o),
                },
            );
        }
        Ok(hub)
    }

    fn take_channel_id(&mut self) -> u32 {
        let id = self.next_channel;
        self.next_channel += 1;
        id
    }

    /// Starts the hub on a thread of its own (its fabric ports stay on it), serving until
    /// `stop` is set or every sender of `from_viewers` is gone.
    pub fn spawn(
        opts: HubOptions,
        from_viewers: Receiver<FromViewer>,
        stop: Arc<AtomicBool>,
    ) -> Result<std::thread::JoinHandle<()>, skillfab_proto::Error> {
        let (ready_tx, ready) = std::sync::mpsc::sync_channel(1);
        let thread = std::thread::Builder::new()
            .name("view-hub".into())
            .spawn(move || match Hub::new(opts) {
                Ok(hub) => {
                    let _ = ready_tx.send(Ok(()));
                    hub.run(&from_viewers, &stop);
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                }
            })
            .map_err(|e| skillfab_proto::Error::transport("view hub thread", e))?;
        match ready.recv() {
            Ok(Ok(())) => Ok(thread),
            Ok(Err(e)) => Err(e),
            Err(e) => Err(skillfab_proto::Error::transport("view hub thread", e)),
        }
    }

    /// Serves until `stop` is set or every viewer's connection thread is gone.
    fn run(mut self, from_viewers: &Receiver<FromViewer>, stop: &AtomicBool) {
        while !stop.load(Ordering::Relaxed) {
            loop {
                match from_viewers.try_recv() {
                    Ok(m) => self.take(m),
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => return,
                }
            }
            self.connect();
            if self.last_discover.is_none_or(|t| t.elapsed() >= DISCOVER) {
                self.discover();
            }
            self.events();
            self.topics();
            self.logs();
            self.truth();
            if self.last_static.elapsed() >= STATIC_TF {
                self.last_static = Instant::now();
                let tf = self.static_tf();
                self.send_own(Own::Tf, &tf);
            }
        }
    }

    /// Connects to the manager when there is none (it may start after the view, or restart).
    fn connect(&mut self) {
        if self.client.is_some() {
            return;
        }
        let Ok(mut c) = Client::connect(&self.opts.domain) else {
            std::thread::sleep(POLL);
            return;
        };
        c.set_timeout(REQUEST_TIMEOUT);
        if let Err(e) = c.subscribe() {
            tracing::warn!(error = %e, "events not subscribed");
        }
        match c.plan() {
            Ok(p) => {
                self.plan_cycle = p
                    .as_ref()
                    .map_or(0, |p| p.status.iter().map(|(_, c)| *c).max().unwrap_or(0));
                self.plan = p;
            }
            Err(e) => tracing::warn!(error = %e, "plan not read"),
        }
        tracing::info!(domain = %self.opts.domain.name(), "connected to the manager");
        self.client = Some(c);
        self.last_discover = None;
        if self.plan.is_some() {
            self.send_plan();
        }
    }

    fn lost_manager(&mut self, e: &ClientError) {
        tracing::warn!(error = %e, "manager lost; waiting for it");
        self.client = None;
    }

    /// Opens a channel for each topic of the domain not seen yet, and advertises them.
    fn discover(&mut self) {
        self.last_discover = Some(Instant::now());
        let Some(c) = &self.client else {
            return;
        };
        let skills = match c.list() {
            Ok(s) => s,
            Err(e) => return self.lost_manager(&e),
        };
        let mut topics: Vec<(String, String)> = skills
            .iter()
            .flat_map(|s| s.outputs.iter().chain(&s.inputs))
            .map(|p| (p.topic.clone(), p.type_name.clone()))
            .collect();
        topics.sort();
        topics.dedup_by(|a, b| a.0 == b.0);
        let mut added = Vec::new();
        for (topic, type_name) in topics {
            if self.by_topic.contains_key(&topic) {
                continue;
            }
            let schema = match c.topic_schema(&topic) {
                Ok(s) => s,
                Err(e) => {
                    tracing::debug!(topic, error = %e, "topic not opened yet");
                    continue;
                }
            };
            let reader = match RawReader::open(&self.node, &topic, &schema) {
                Ok(r) => r,
                Err(e) => {
                    tracing::warn!(topic, error = %e, "topic not readable");
                    continue;
                }
            };
            if type_name == "skillfab.Sonar" && self.robot.sonar_topic.is_none() {
                self.robot.ranges = resolve(&schema, "range").ok();
                self.robot.sonar_topic = Some(topic.clone());
            }
            if type_name == "skillfab.Odometry" && self.robot.odom_topic.is_none() {
                self.robot.odom = match (
                    resolve(&schema, "x"),
                    resolve(&schema, "y"),
                    resolve(&schema, "theta"),
                ) {
                    (Ok(x), Ok(y), Ok(t)) => Some([x, y, t]),
                    _ => None,
                };
                self.robot.odom_topic = Some(topic.clone());
            }
            let id = self.next_channel;
            self.next_channel += 1;
            let channel = Channel {
                id,
                topic: format!("/{topic}"),
                encoding: "cdr".into(),
                schema_name: ros2msg::schema_name(&schema.type_name),
                schema: ros2msg::schema_text(&schema),
                schema_encoding: "ros2msg".into(),
            };
            tracing::info!(topic, r#type = %schema.type_name, channel = id, "advertised");
            added.push(channel.clone());
            self.by_topic.insert(topic, id);
            self.channels.insert(
                id,
                ChannelState {
                    channel,
                    source: Source::Topic(Box::new(TopicReader { schema, reader })),
                },
            );
        }
        if !added.is_empty() {
            let m = ServerMessage::Advertise { channels: added };
            for v in self.viewers.values() {
                v.outbox.text(&m);
            }
        }
    }

    /// Sends `frame_of(subscription)` to each viewer subscribed to `channel` whose throttle
    /// lets it through now; builds the payload only if one does.
    fn fan_out(&mut self, channel: u32, payload: &mut dyn FnMut() -> Option<Vec<u8>>) {
        let now = Instant::now();
        let mut built: Option<Option<Vec<u8>>> = None;
        let time = unix_now_ns();
        for v in self.viewers.values_mut() {
            let Some((subs, last)) = v.by_channel.get_mut(&channel) else {
                continue;
            };
            if let (Some(hz), Some(l)) = (v.wishes.max_hz.or(self.opts.max_hz), *last)
                && now.duration_since(l).as_secs_f64() < 1.0 / hz
            {
                continue;
            }
            let Some(p) = built.get_or_insert_with(&mut *payload) else {
                return;
            };
            *last = Some(now);
            for s in subs.iter() {
                v.outbox.data(protocol::message_data(*s, time, p));
            }
        }
    }

    fn send_own(&mut self, own: Own, msg: &Json) {
        if let Some(&id) = self.own.get(&own) {
            self.fan_out(id, &mut || Some(msg.to_string().into_bytes()));
        }
    }

    /// Reads every topic; each sample goes out on its channel, and the sonar and odometry
    /// samples feed `/robot` and `/tf`.
    fn topics(&mut self) {
        let mut samples: Vec<(u32, Vec<u8>)> = Vec::new();
        let mut sonar: Option<Vec<f64>> = None;
        let mut odom: Option<[f64; 3]> = None;
        for (&id, ch) in &mut self.channels {
            let Source::Topic(topic) = &mut ch.source else {
                continue;
            };
            let reader = &mut topic.reader;
            let is_sonar = self.robot.sonar_topic.as_deref() == Some(&ch.channel.topic[1..]);
            let is_odom = self.robot.odom_topic.as_deref() == Some(&ch.channel.topic[1..]);
            let wanted = self
                .viewers
                .values()
                .any(|v| v.by_channel.contains_key(&id));
            let r = reader.drain(&mut |bytes, _| {
                if wanted {
                    samples.push((id, bytes.to_vec()));
                }
                if is_sonar
                    && let Some(Value::Array(a)) =
                        self.robot.ranges.as_ref().and_then(|p| p.read(bytes))
                {
                    sonar = Some(a.iter().map(|v| v.as_f64().unwrap_or(f64::NAN)).collect());
                }
                if is_odom && let Some([x, y, t]) = &self.robot.odom {
                    let num = |p: &FieldPath| p.read(bytes).and_then(|v| v.as_f64());
                    if let (Some(x), Some(y), Some(t)) = (num(x), num(y), num(t)) {
                        odom = Some([x, y, t]);
                    }
                }
            });
            if let Err(e) = r {
                tracing::warn!(topic = %ch.channel.topic, error = %e, "topic not read");
            }
        }
        for (id, bytes) in samples {
            let Some(ChannelState {
                source: Source::Topic(topic),
                ..
            }) = self.channels.get(&id)
            else {
                continue;
            };
            let schema = topic.schema.clone();
            self.fan_out(id, &mut || {
                let mut out = Vec::with_capacity(bytes.len() + 8);
                cdr::encode(&schema, &bytes, &mut out);
                Some(out)
            });
        }
        let now = stamp(unix_now_ns());
        if let Some(r) = sonar {
            self.send_own(Own::Robot, &scene::robot_update("base_link", &r, &now));
        }
        if let Some([x, y, t]) = odom {
            let tf = json!({"transforms": [{"timestamp": now, "parent_frame_id": "odom",
                "child_frame_id": "base_link", "translation": {"x": x, "y": y, "z": 0.0},
                "rotation": scene::quaternion(t)}]});
            self.send_own(Own::Tf, &tf);
        }
    }

    fn static_tf(&self) -> Json {
        let (at, yaw) = self
            .opts
            .scene
            .as_ref()
            .map_or(([0.0; 3], 0.0), Scene::odom_origin);
        json!({"transforms": [{"timestamp": stamp(unix_now_ns()), "parent_frame_id": "map",
            "child_frame_id": "odom", "translation": {"x": at[0], "y": at[1], "z": at[2]},
            "rotation": scene::quaternion(yaw)}]})
    }

    /// The newest ground-truth record, as `map → truth`, when the file grew.
    fn truth(&mut self) {
        if self.last_truth.elapsed() < TRUTH {
            return;
        }
        self.last_truth = Instant::now();
        let Some(path) = &self.opts.truth else {
            return;
        };
        let Ok(meta) = std::fs::metadata(path) else {
            return;
        };
        if meta.len() == self.truth_len {
            return;
        }
        self.truth_len = meta.len();
        let Some(r) = last_truth_record(path, meta.len()) else {
            return;
        };
        let tf = json!({"transforms": [{"timestamp": stamp(unix_now_ns()),
            "parent_frame_id": "map", "child_frame_id": "truth",
            "translation": {"x": r.x, "y": r.y, "z": f64::from(r.floor) * scene::FLOOR_HEIGHT},
            "rotation": scene::quaternion(r.theta)}]});
        self.send_own(Own::Tf, &tf);
    }

    fn events(&mut self) {
        let mut wait = POLL;
        loop {
            let Some(c) = &mut self.client else {
                return;
            };
            let ev = match c.next_event(wait) {
                Ok(Some(ev)) => ev,
                Ok(None) => return,
                Err(e) => return self.lost_manager(&e),
            };
            wait = Duration::ZERO;
            self.event(&ev);
        }
    }

    fn event(&mut self, ev: &Event) {
        let log = json!({"timestamp": stamp(unix_now_ns()), "level": event_level(&ev.kind),
            "message": format!("cycle {}: {}", ev.cycle, skillfab_proto::json::event_json(ev)),
            "name": "manager", "file": "", "line": 0});
        self.send_own(Own::Events, &log);
        match &ev.kind {
            EventKind::ParamChanged {
                skill, param, new, ..
            } => {
                let name = format!("/{skill}/{param}");
                let m = ServerMessage::ParameterValues {
                    parameters: vec![parameter(name.clone(), *new)],
                    id: None,
                };
                for v in self.viewers.values() {
                    if v.params
                        .as_ref()
                        .is_some_and(|s| s.is_empty() || s.contains(&name))
                    {
                        v.outbox.text(&m);
                    }
                }
            }
            EventKind::PlanStarted { .. } => self.read_plan(),
            EventKind::PlanChanged {
                plan,
                cycle,
                changes,
            } => {
                let applied = match &mut self.plan {
                    Some(p) if p.plan == *plan => p.apply(changes, *cycle).is_ok(),
                    _ => false,
                };
                self.plan_cycle = *cycle;
                if applied {
                    self.send_plan();
                } else {
                    // A plan this view has not seen the shape of: read it whole.
                    self.read_plan();
                }
            }
            EventKind::PlanEnded { plan, status } => {
                if let Some(p) = self.plan.take().filter(|p| p.plan == *plan) {
                    let mut j = plan_json(&p, ev.cycle);
                    j["ended"] = json!(status.as_str());
                    self.send_own(Own::Plan, &j);
                }
            }
            _ => {}
        }
    }

    /// Reads the running plan whole (a plan started, or this view missed its shape).
    fn read_plan(&mut self) {
        match self.client.as_ref().map(Client::plan) {
            Some(Ok(p)) => {
                self.plan = p;
                self.send_plan();
            }
            Some(Err(e)) => self.lost_manager(&e),
            None => {}
        }
    }

    fn send_plan(&mut self) {
        if let Some(p) = &self.plan {
            let j = plan_json(p, self.plan_cycle);
            self.send_own(Own::Plan, &j);
        }
    }

    fn logs(&mut self) {
        let Some(c) = &mut self.client else {
            return;
        };
        let lines: Vec<LogLine> = match c.log_lines() {
            Ok(l) => l,
            Err(e) => return self.lost_manager(&e),
        };
        for l in lines {
            let msg = json!({"timestamp": stamp(unix_now_ns()), "level": log_level(l.level),
                "message": l.to_string(), "name": l.skill, "file": l.target, "line": 0});
            self.send_own(Own::Log, &msg);
        }
    }

    fn take(&mut self, m: FromViewer) {
        match m {
            FromViewer::Joined { id, outbox, wishes } => {
                outbox.text(&ServerMessage::ServerInfo {
                    name: format!("skillfab view ({})", self.opts.domain.name()),
                    capabilities: vec![
                        "parameters".into(),
                        "parametersSubscribe".into(),
                        "services".into(),
                    ],
                    supported_encodings: vec!["json".into()],
                    metadata: [
                        ("domain".to_string(), json!(self.opts.domain.name())),
                        (
                            "world".to_string(),
                            json!(self.opts.scene.as_ref().map(|s| s.name.clone())),
                        ),
                    ]
                    .into_iter()
                    .collect(),
                    session_id: format!("{}-{}", std::process::id(), unix_now_ns()),
                });
                outbox.text(&ServerMessage::Advertise {
                    channels: self.channels.values().map(|c| c.channel.clone()).collect(),
                });
                outbox.text(&ServerMessage::AdvertiseServices {
                    services: services(),
                });
                self.viewers.insert(
                    id,
                    Viewer {
                        outbox,
                        wishes,
                        subs: HashMap::new(),
                        by_channel: HashMap::new(),
                        params: None,
                    },
                );
            }
            FromViewer::Left { id } => {
                self.viewers.remove(&id);
            }
            FromViewer::Message { id, message } => self.request(id, message),
            FromViewer::Call { id, call } => self.call(id, &call),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skillfab_proto::control::PlanNode;

    #[test]
    fn the_last_complete_truth_record_is_read_from_the_files_tail() {
        let dir = std::env::temp_dir().join(format!("view-truth-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("t.csv");
        let mut text = format!("{}\n", denning_sim::truth::TruthRecord::HEADER);
        std::fs::write(&f, &text).unwrap();
        assert!(last_truth_record(&f, text.len() as u64).is_none());
        for i in 0..200 {
            text.push_str(&format!("{i}.0,{i}.5,2.0,0.1,0,0,0,0,0,0,0,1,0,0,0\n"));
        }
        text.push_str("200.0,9");
        std::fs::write(&f, &text).unwrap();
        let r = last_truth_record(&f, text.len() as u64).unwrap();
        assert_eq!((r.t, r.x, r.floor), (199.0, 199.5, 1));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_running_branch_follows_running_children_from_the_root() {
        let node = |id, parent, name: &str, kind: &str| PlanNode {
            id,
            parent,
            name: name.into(),
            kind: kind.into(),
            detail: String::new(),
        };
        let tree = PlanTree {
            plan: "p".into(),
            nodes: vec![
                node(0, None, "", "Sequence"),
                node(1, Some(0), "find", "Fallback"),
                node(2, Some(1), "a", "Action"),
                node(3, Some(1), "b", "Action"),
                node(4, Some(0), "c", "Action"),
            ],
            status: vec![
                (NodeStatus::Running, 1),
                (NodeStatus::Running, 2),
                (NodeStatus::Failure, 3),
                (NodeStatus::Running, 3),
                (NodeStatus::Idle, 0),
            ],
        };
        let branch = running_branch(&tree);
        let branch: Vec<(usize, &str)> = branch.iter().map(|(d, n)| (*d, n.as_str())).collect();
        assert_eq!(
            branch,
            [(0, "Sequence"), (1, "Fallback find"), (2, "Action b")]
        );
        let mut both = tree.clone();
        both.status[4] = (NodeStatus::Running, 4);
        assert_eq!(
            running_branch(&both).len(),
            4,
            "both branches of a sequence's children"
        );
        let j = plan_json(&tree, 9);
        assert_eq!(j["nodes"][2]["status"], json!("failure"));
        assert_eq!(j["nodes"][3]["since_cycle"], json!(3));
        assert_eq!(j["cycle"], json!(9));
    }
}
