//! `skillfab console`: the debugging interface — a terminal UI next to a running fabric.
//!
//! ## Layout
//! - [`app`]: the state ([`App`]) and what keys and fabric updates do to it; pure.
//! - [`view`]: [`render`]`(&App, &mut Frame)`; pure.
//! - this module: the worker thread, which is just another control client (it owns a
//!   [`Client`] and a [`LogReader`], polls the manager a few times a second, carries out
//!   commands, reconnects when the manager goes and comes back), and the terminal loop, which
//!   only draws and reads keys. A slow or absent manager never freezes the screen, and the
//!   console never holds up a cycle: the manager answers it between cycles like any client.

#![warn(missing_docs)]

pub mod app;
pub mod view;

#[cfg(test)]
mod tests;

pub use app::{App, Command, Update};
pub use view::render;

use anyhow::Context;
use app::{Dir, PlanView, PortView, Snapshot};
use ratatui::crossterm::event::{self, Event, KeyEventKind};
use skillfab_client::{Address, Client, ClientError};
use skillfab_proto::control::{EventKind, PortInfo, SkillInfo};
use skillfab_proto::log::LogReader;
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::time::{Duration, Instant};

/// How often the worker reads the fabric.
const REFRESH: Duration = Duration::from_millis(250);
/// How often it looks for a manager while there is none.
const RECONNECT: Duration = Duration::from_millis(500);
/// How long one request may take before the manager counts as gone.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(2);
/// Cycle latencies shown (the sparkline is as wide as the terminal, at most this).
const HISTORY: u32 = 400;

/// Runs the console on the current terminal until `q` (or SIGINT/SIGTERM), on the domain
/// `address` names: on this host, or on another through its bridge.
pub fn run(address: Address) -> anyhow::Result<()> {
    let (cmd_tx, cmd_rx) = channel();
    let (up_tx, up_rx) = channel();
    let app = App::new(address.domain());
    let worker = std::thread::Builder::new()
        .name("console-worker".into())
        .spawn(move || Worker::new(address, up_tx).run(&cmd_rx))
        .context("starting the console's worker thread")?;
    // ratatui's init puts the terminal back on a panic too.
    let mut terminal = ratatui::try_init().context("setting up the terminal")?;
    let result = ui_loop(&mut terminal, app, &cmd_tx, &up_rx);
    ratatui::restore();
    drop(cmd_tx);
    let _ = worker.join();
    result
}

fn ui_loop(
    terminal: &mut ratatui::DefaultTerminal,
    mut app: App,
    commands: &Sender<Command>,
    updates: &Receiver<Update>,
) -> anyhow::Result<()> {
    loop {
        terminal.draw(|f| render(&app, f)).context("drawing")?;
        // Keys first, then whatever the worker found; a resize simply draws again.
        if event::poll(Duration::from_millis(50)).context("reading the terminal")?
            && let Event::Key(key) = event::read().context("reading the terminal")?
            && key.kind != KeyEventKind::Release
            && let Some(c) = app.on_key(key)
        {
            let _ = commands.send(c);
        }
        while let Ok(u) = updates.try_recv() {
            if let Some(c) = app.apply(u) {
                let _ = commands.send(c);
            }
        }
        if app.quit {
            return Ok(());
        }
    }
}

/// The console's control client, on its own thread.
struct Worker {
    /// Where the domain's manager is.
    address: Address,
    updates: Sender<Update>,
    client: Option<Client>,
    /// The local log stream (a remote domain's lines come through the client).
    logs: Option<LogReader>,
    selected: Option<String>,
    last_down: Option<String>,
    /// The plan as last sent to the screen; fetched whole when the client connects (or
    /// events were lost, or a new tree arrived), then changed by `PlanChanged` events.
    plan: Option<PlanView>,
    /// The plan must be fetched whole.
    plan_stale: bool,
}

/// The error as one line (its message carries its cause).
fn describe(e: &ClientError) -> String {
    format!("{e}")
}

impl Worker {
    fn new(address: Address, updates: Sender<Update>) -> Worker {
        let logs = match &address {
            Address::Remote { .. } => None,
            Address::Local(domain) => {
                LogReader::open(domain, &format!("console-{}", std::process::id()))
                    .map_err(|e| {
                        let _ = updates.send(Update::Failed(format!("no log stream: {e}")));
                    })
                    .ok()
            }
        };
        Worker {
            address,
            updates,
            client: None,
            logs,
            selected: None,
            last_down: None,
            plan: None,
            plan_stale: true,
        }
    }

    fn run(mut self, commands: &Receiver<Command>) {
        let mut next_refresh = Instant::now();
        loop {
            loop {
                match commands.try_recv() {
                    Ok(Command::Select(s)) => {
                        self.selected = s;
                        next_refresh = Instant::now();
                    }
                    Ok(c) => {
                        self.command(c);
                        next_refresh = Instant::now();
                    }
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => return,
                }
            }
            if Instant::now() >= next_refresh {
                let connected = self.refresh();
                next_refresh = Instant::now() + if connected { REFRESH } else { RECONNECT };
            }
            self.follow_plan();
            if let Some(logs) = &self.logs {
                if let Ok(lines) = logs.poll()
                    && !lines.is_empty()
                {
                    let _ = self.updates.send(Update::Logs(lines));
                }
                if !logs.wait(Duration::from_millis(20)) {
                    let _ = self.updates.send(Update::Quit);
                    return;
                }
            } else {
                if let Some(c) = self.client.as_mut()
                    && let Ok(lines) = c.log_lines()
                    && !lines.is_empty()
                {
                    let _ = self.updates.send(Update::Logs(lines));
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }

    fn down(&mut self, why: String) {
        self.client = None;
        if self.last_down.as_ref() != Some(&why) {
            self.last_down = Some(why.clone());
        }
        let _ = self.updates.send(Update::Disconnected(why));
    }

    /// The client, connecting if needed (a new client subscribes to the events and fetches
    /// the plan afresh).
    fn client(&mut self) -> Option<&Client> {
        if self.client.is_none() {
            match self.address.connect() {
                Ok(mut c) => {
                    c.set_timeout(REQUEST_TIMEOUT);
                    if let Err(e) = c.subscribe() {
                        let _ = self
                            .updates
                            .send(Update::Failed(format!("no events, no live plan: {e}")));
                    }
                    self.client = Some(c);
                    self.last_down = None;
                    self.plan_stale = true;
                }
                Err(e) => {
                    self.down(describe(&e));
                    return None;
                }
            }
        }
        self.client.as_ref()
    }

    /// Reads everything the screen shows; `false` if there is no manager.
    fn refresh(&mut self) -> bool {
        let selected = self.selected.clone();
        let Some(c) = self.client() else {
            return false;
        };
        let snap = (|| -> Result<Snapshot, ClientError> {
            let skills = c.list()?;
            let stats = c.stats()?;
            let (_, latencies) = c.latencies(HISTORY)?;
            let (log_file, io_skills) = c.logging()?;
            let ports = match selected
                .as_ref()
                .and_then(|n| skills.iter().find(|s| s.name == *n))
            {
                Some(s) => read_ports(c, s, &skills)?,
                None => Vec::new(),
            };
            Ok(Snapshot {
                skills,
                stats,
                latencies,
                ports_of: selected.clone(),
                ports,
                log_file,
                io_skills,
            })
        })();
        match snap {
            Ok(s) => {
                let _ = self.updates.send(Update::Snapshot(Box::new(s)));
                true
            }
            Err(e) => {
                self.down(describe(&e));
                false
            }
        }
    }

    /// Takes in the plan's events (a tree fetched whole when needed) and sends the screen the
    /// plan when it changed.
    fn follow_plan(&mut self) {
        let Some(c) = self.client.as_mut() else {
            return;
        };
        let lost = c.lost_events();
        let mut changed = false;
        loop {
            let ev = match c.next_event(Duration::ZERO) {
                Ok(Some(ev)) => ev,
                Ok(None) => break,
                Err(_) => {
                    self.plan_stale = true;
                    break;
                }
            };
            match (ev.kind, self.plan.as_mut()) {
                (
                    EventKind::PlanChanged {
                        plan,
                        cycle,
                        changes,
                    },
                    Some(p),
                ) if p.tree.plan == plan && p.ended.is_none() => {
                    // A node the tree does not have: the tree is not the manager's.
                    self.plan_stale |= p.tree.apply(&changes, cycle).is_err();
                    changed = true;
                }
                (EventKind::PlanChanged { .. } | EventKind::PlanStarted { .. }, _) => {
                    self.plan_stale = true
                }
                (EventKind::PlanEnded { plan, status }, Some(p)) if p.tree.plan == plan => {
                    p.ended = Some(status);
                    changed = true;
                }
                _ => {}
            }
        }
        self.plan_stale |= c.lost_events() != lost;
        if self.plan_stale {
            match c.plan() {
                // No plan runs: the last one, ended, stays on the screen.
                Ok(None) => {}
                Ok(Some(tree)) => {
                    self.plan = Some(PlanView { tree, ended: None });
                    changed = true;
                }
                Err(_) => return,
            }
            self.plan_stale = false;
        }
        if changed {
            let _ = self
                .updates
                .send(Update::Plan(self.plan.clone().map(Box::new)));
        }
    }

    fn command(&mut self, cmd: Command) {
        let Some(c) = self.client() else {
            let _ = self
                .updates
                .send(Update::Failed("not connected to a manager".into()));
            return;
        };
        let (done, result) = match &cmd {
            Command::Select(_) => return,
            Command::Activate(s, true) => (format!("{s} activated"), c.activate(&[s.as_str()])),
            Command::Activate(s, false) => {
                (format!("{s} deactivated"), c.deactivate(&[s.as_str()]))
            }
            Command::SetParam(s, p, v) => (format!("{s}.{p} = {v}"), c.set_param(s, p, v)),
            Command::Priority(s, p) => (format!("priority of {s} = {p}"), c.set_priority(s, *p)),
            Command::Run => ("cycling".into(), c.run()),
            Command::Stop => ("stopped".into(), c.stop()),
            Command::Step => match c.step(1) {
                Ok(k) => (format!("stepped to cycle {k}"), Ok(())),
                Err(e) => (String::new(), Err(e)),
            },
            Command::IoLog(s, on) => (
                if *on {
                    format!("logging {s}'s samples to the fabric log")
                } else {
                    format!("no longer logging {s}'s samples")
                },
                c.set_io_log(s, *on),
            ),
        };
        let update = match result {
            Ok(()) => Update::Done(done),
            // The manager said no: show why, stay connected.
            Err(ClientError::Refused(e)) => Update::Failed(e.to_string()),
            Err(e) => {
                let text = describe(&e);
                self.down(text.clone());
                Update::Failed(text)
            }
        };
        let _ = self.updates.send(update);
    }
}

/// The latest value of each of `s`'s ports: outputs directly, inputs through their producer.
fn read_ports(
    c: &Client,
    s: &SkillInfo,
    skills: &[SkillInfo],
) -> Result<Vec<PortView>, ClientError> {
    let mut out = Vec::new();
    let read =
        |path: &str| -> Result<Result<(skillfab_proto::value::Value, u64), String>, ClientError> {
            match c.query(path) {
                Ok(v) => Ok(Ok(v)),
                Err(ClientError::Refused(e)) => Ok(Err(e.to_string())),
                Err(e) => Err(e),
            }
        };
    for PortInfo {
        port,
        topic,
        type_name: ty,
    } in &s.inputs
    {
        let (source, value) = if let Some(channel) = topic.strip_prefix("channel/") {
            let path = format!("channel.{channel}.command");
            let v = read(&path)?;
            (path, v)
        } else {
            match skills.iter().find_map(|p| {
                p.outputs
                    .iter()
                    .find(|o| o.topic == *topic)
                    .map(|o| format!("{}.{}", p.name, o.port))
            }) {
                Some(path) => {
                    let v = read(&path)?;
                    (path, v)
                }
                None => (
                    format!("topic {topic}"),
                    Err(format!("nobody produces '{topic}'")),
                ),
            }
        };
        out.push(PortView {
            dir: Dir::In,
            port: port.clone(),
            type_name: ty.clone(),
            source,
            value,
        });
    }
    for PortInfo {
        port,
        topic,
        type_name: ty,
    } in &s.outputs
    {
        let path = format!("{}.{port}", s.name);
        out.push(PortView {
            dir: Dir::Out,
            port: port.clone(),
            type_name: ty.clone(),
            source: format!("topic {topic}"),
            value: read(&path)?,
        });
    }
    Ok(out)
}
