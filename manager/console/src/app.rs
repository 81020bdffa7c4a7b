//! The console's state and what keys do to it: pure, no terminal and no fabric, so tests
//! drive it directly. The worker's [`Update`]s come in through [`App::apply`]; keys through
//! [`App::on_key`], which returns the [`Command`]s for the worker.

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use skillfab_proto::control::{NodeStatus, SkillInfo, SkillState, Stats};
use skillfab_proto::log::{Level, LogLine};
use skillfab_proto::value::Value;
use std::collections::VecDeque;

/// Log lines the console keeps (all skills together).
pub const LOG_KEEP: usize = 2000;

/// Lines a page key scrolls the plan pane by.
pub const PLAN_PAGE: usize = 20;

/// Whether a port is read or written by the skill.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dir {
    /// An input (its value is the producer's output).
    In,
    /// An output.
    Out,
}

/// One port of the selected skill with its latest value.
#[derive(Debug, Clone, PartialEq)]
pub struct PortView {
    /// Input or output.
    pub dir: Dir,
    /// The port's name.
    pub port: String,
    /// The message type name.
    pub type_name: String,
    /// Where the value comes from (`skill.port` of the producer, or the topic).
    pub source: String,
    /// The latest value and its cycle, or why there is none.
    pub value: Result<(Value, u64), String>,
}

/// What the worker read from the manager in one refresh.
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshot {
    /// Every registered skill, in registration order.
    pub skills: Vec<SkillInfo>,
    /// Cycle statistics.
    pub stats: Stats,
    /// Recent cycle latencies (µs), oldest first.
    pub latencies: Vec<f32>,
    /// The skill whose ports are in `ports`.
    pub ports_of: Option<String>,
    /// Its ports and their values.
    pub ports: Vec<PortView>,
    /// The manager's fabric log file.
    pub log_file: Option<String>,
    /// Skills whose samples are logged.
    pub io_skills: Vec<String>,
}

/// The plan as the console shows it: the manager's tree, kept after the plan ended.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanView {
    /// The tree and each node's status.
    pub tree: skillfab_proto::control::PlanTree,
    /// The plan ended, its root with this status (the tree is its last state).
    pub ended: Option<NodeStatus>,
}

/// Which pane fills the screen under the latency line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pane {
    /// The skills table and the selected skill.
    Skills,
    /// The running plan as a tree (`t`).
    Plan,
}

/// What the worker tells the console.
#[derive(Debug, Clone, PartialEq)]
pub enum Update {
    /// A fresh view of the fabric.
    Snapshot(Box<Snapshot>),
    /// No manager (or it stopped answering): why. The worker keeps trying.
    Disconnected(String),
    /// A command was carried out.
    Done(String),
    /// A command was refused or failed.
    Failed(String),
    /// New log lines.
    Logs(Vec<LogLine>),
    /// The plan changed (`None`: no plan has run since the console connected).
    Plan(Option<Box<PlanView>>),
    /// SIGINT/SIGTERM: leave.
    Quit,
}

/// What the console asks the worker to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// Show this skill's ports from now on.
    Select(Option<String>),
    /// Activate (`true`) or deactivate a skill.
    Activate(String, bool),
    /// Set a parameter from text.
    SetParam(String, String, String),
    /// Set a priority.
    Priority(String, i32),
    /// Start cycling.
    Run,
    /// Stop cycling.
    Stop,
    /// One cycle.
    Step,
    /// Log a skill's samples (`true`) or stop.
    IoLog(String, bool),
}

/// An open input line.
#[derive(Debug, Clone, PartialEq)]
pub enum Prompt {
    /// A new value for a parameter.
    Param {
        /// Skill.
        skill: String,
        /// Parameter.
        param: String,
        /// What was typed.
        text: String,
    },
    /// A new priority.
    Priority {
        /// Skill.
        skill: String,
        /// What was typed.
        text: String,
    },
}

/// The connection to the manager, as far as the console knows.
#[derive(Debug, Clone, PartialEq)]
pub enum Link {
    /// Not connected yet, or lost: why.
    Down(String),
    /// Snapshots arrive.
    Up,
}

/// The console's whole state.
#[derive(Debug, Clone)]
pub struct App {
    /// The domain shown.
    pub domain: String,
    /// The connection.
    pub link: Link,
    /// The latest snapshot (kept while disconnected, shown greyed).
    pub snap: Option<Snapshot>,
    /// Selected row of the skills table.
    pub selected: usize,
    /// The selected skill's name (the selection follows it when the list changes).
    pub selected_name: Option<String>,
    /// A selected skill that left the list (died, restarting): selected again when it comes
    /// back, unless a key moved the selection meanwhile.
    pub lost: Option<String>,
    /// Selected parameter of the selected skill.
    pub param: usize,
    /// Recent log lines of every skill, oldest first.
    pub logs: VecDeque<LogLine>,
    /// Show every level of the selected skill's lines (else warnings and errors only).
    pub verbose: bool,
    /// The last outcome: (is an error, text).
    pub status: Option<(bool, String)>,
    /// An open input line.
    pub prompt: Option<Prompt>,
    /// The console should exit.
    pub quit: bool,
    /// The pane shown.
    pub pane: Pane,
    /// The running plan (or the last one, ended).
    pub plan: Option<PlanView>,
    /// The plan pane's first line (a node number) when not following.
    pub plan_scroll: usize,
    /// The plan pane keeps the running branch in view (until a scroll key is pressed).
    pub plan_follow: bool,
}

impl App {
    /// A console for `domain`, not connected yet.
    pub fn new(domain: &str) -> App {
        App {
            domain: domain.to_string(),
            link: Link::Down("connecting".into()),
            snap: None,
            selected: 0,
            selected_name: None,
            lost: None,
            param: 0,
            logs: VecDeque::new(),
            verbose: false,
            status: None,
            prompt: None,
            quit: false,
            pane: Pane::Skills,
            plan: None,
            plan_scroll: 0,
            plan_follow: true,
        }
    }

    /// The skills shown.
    pub fn skills(&self) -> &[SkillInfo] {
        self.snap.as_ref().map_or(&[], |s| s.skills.as_slice())
    }

    /// The selected skill.
    pub fn selected_skill(&self) -> Option<&SkillInfo> {
        self.skills().get(self.selected)
    }

    /// The selected skill's ports, if the snapshot has them.
    pub fn ports(&self) -> &[PortView] {
        match (&self.snap, &self.selected_name) {
            (Some(s), Some(n)) if s.ports_of.as_ref() == Some(n) => &s.ports,
            _ => &[],
        }
    }

    /// The selected skill's log lines to show: all levels when verbose, else warnings and up.
    pub fn skill_logs(&self) -> impl Iterator<Item = &LogLine> {
        let name = self.selected_name.clone();
        let verbose = self.verbose;
        self.logs
            .iter()
            .filter(move |l| Some(&l.skill) == name.as_ref() && (verbose || l.level <= Level::Warn))
    }

    /// Whether the selected skill's samples are logged.
    pub fn io_logged(&self, skill: &str) -> bool {
        self.snap
            .as_ref()
            .is_some_and(|s| s.io_skills.iter().any(|n| n == skill))
    }

    fn ok(&mut self, text: impl Into<String>) {
        self.status = Some((false, text.into()));
    }

    fn err(&mut self, text: impl Into<String>) {
        self.status = Some((true, text.into()));
    }

    /// Takes in what the worker found.
    pub fn apply(&mut self, u: Update) -> Option<Command> {
        match u {
            Update::Snapshot(s) => {
                self.link = Link::Up;
                self.snap = Some(*s);
                return self.reselect();
            }
            Update::Disconnected(why) => self.link = Link::Down(why),
            Update::Done(text) => self.ok(text),
            Update::Failed(text) => self.err(text),
            Update::Logs(lines) => {
                self.logs.extend(lines);
                while self.logs.len() > LOG_KEEP {
                    self.logs.pop_front();
                }
            }
            Update::Plan(p) => self.plan = p.map(|p| *p),
            Update::Quit => self.quit = true,
        }
        None
    }

    /// Keeps the selection on the same skill when the list changes; tells the worker when
    /// the selected skill changed.
    fn reselect(&mut self) -> Option<Command> {
        let names: Vec<String> = self.skills().iter().map(|s| s.name.clone()).collect();
        let at = |n: &String| names.iter().position(|x| x == n);
        if let Some(i) = self.lost.as_ref().and_then(at) {
            self.selected = i;
            self.lost = None;
        } else if let Some(i) = self.selected_name.as_ref().and_then(at) {
            self.selected = i;
        } else {
            if self.lost.is_none() {
                self.lost = self.selected_name.clone();
            }
            self.selected = self.selected.min(names.len().saturating_sub(1));
        }
        self.set_selected()
    }

    fn set_selected(&mut self) -> Option<Command> {
        let name = self.selected_skill().map(|s| s.name.clone());
        let nparams = self.selected_skill().map_or(0, |s| s.params.len());
        self.param = self.param.min(nparams.saturating_sub(1));
        if name != self.selected_name {
            self.selected_name = name.clone();
            self.param = 0;
            return Some(Command::Select(name));
        }
        None
    }

    fn connected(&mut self) -> bool {
        if self.link != Link::Up {
            self.err("not connected to a manager");
            return false;
        }
        true
    }

    /// What a key does; the commands go to the worker.
    pub fn on_key(&mut self, key: KeyEvent) -> Option<Command> {
        if key.modifiers.contains(KeyModifiers::CONTROL) && key.code == KeyCode::Char('c') {
            self.quit = true;
            return None;
        }
        if self.prompt.is_some() {
            return self.on_prompt_key(key.code);
        }
        if key.code == KeyCode::Char('t') {
            self.pane = match self.pane {
                Pane::Skills => Pane::Plan,
                Pane::Plan => Pane::Skills,
            };
            return None;
        }
        if self.pane == Pane::Plan {
            return self.on_plan_key(key.code);
        }
        let n = self.skills().len();
        match key.code {
            KeyCode::Char('q') | KeyCode::Esc => {
                self.quit = true;
                None
            }
            KeyCode::Up | KeyCode::Char('k') => {
                self.lost = None;
                self.selected = self.selected.saturating_sub(1);
                self.set_selected()
            }
            KeyCode::Down | KeyCode::Char('j') => {
                self.lost = None;
                if self.selected + 1 < n {
                    self.selected += 1;
                }
                self.set_selected()
            }
            KeyCode::Tab => {
                let np = self.selected_skill().map_or(0, |s| s.params.len());
                if np > 0 {
                    self.param = (self.param + 1) % np;
                }
                None
            }
            KeyCode::BackTab => {
                let np = self.selected_skill().map_or(0, |s| s.params.len());
                if np > 0 {
                    self.param = (self.param + np - 1) % np;
                }
                None
            }
            KeyCode::Char('v') => {
                self.verbose = !self.verbose;
                self.ok(if self.verbose {
                    "verbose: every log line of the selected skill"
                } else {
                    "verbose off: warnings and errors only"
                });
                None
            }
            KeyCode::Char('a') => {
                let s = self.selected_skill()?;
                let (name, on) = (s.name.clone(), s.state != SkillState::Active);
                self.connected().then_some(Command::Activate(name, on))
            }
            KeyCode::Char('e') => {
                let s = self.selected_skill()?;
                let Some(spec) = s.params.get(self.param) else {
                    let name = s.name.clone();
                    self.err(format!("{name} has no parameters"));
                    return None;
                };
                let current = s
                    .values
                    .iter()
                    .find(|(n, _)| *n == spec.name)
                    .map_or(spec.default, |(_, v)| *v);
                self.prompt = Some(Prompt::Param {
                    skill: s.name.clone(),
                    param: spec.name.clone(),
                    text: current.to_string(),
                });
                None
            }
            KeyCode::Char('p') => {
                let s = self.selected_skill()?;
                self.prompt = Some(Prompt::Priority {
                    skill: s.name.clone(),
                    text: s.priority.to_string(),
                });
                None
            }
            KeyCode::Char('l') => {
                let name = self.selected_skill()?.name.clone();
                let on = !self.io_logged(&name);
                self.connected().then_some(Command::IoLog(name, on))
            }
            KeyCode::Char('r') => {
                let running = self.snap.as_ref().is_some_and(|s| s.stats.running);
                self.connected()
                    .then_some(if running { Command::Stop } else { Command::Run })
            }
            KeyCode::Char('s') => self.connected().then_some(Command::Step),
            _ => None,
        }
    }

    /// The deepest running node of the plan (0 when none runs): the place followed.
    pub fn plan_anchor(&self) -> usize {
        self.plan.as_ref().map_or(0, |p| {
            p.tree
                .status
                .iter()
                .rposition(|s| s.0 == NodeStatus::Running)
                .unwrap_or(0)
        })
    }

    /// Keys of the plan pane: scrolling (which stops following the running branch; `f`
    /// follows it again), `r`/`s` as everywhere, `q` to quit.
    fn on_plan_key(&mut self, code: KeyCode) -> Option<Command> {
        let n = self.plan.as_ref().map_or(0, |p| p.tree.nodes.len());
        let last = n.saturating_sub(1);
        // Scrolling from the followed place starts near the deepest running node.
        let at = if self.plan_follow {
            self.plan_anchor().saturating_sub(PLAN_PAGE / 3)
        } else {
            self.plan_scroll
        };
        let mut scroll = |to: usize| {
            self.plan_follow = false;
            self.plan_scroll = to.min(last);
        };
        match code {
            KeyCode::Char('q') | KeyCode::Esc => self.quit = true,
            KeyCode::Up | KeyCode::Char('k') => scroll(at.saturating_sub(1)),
            KeyCode::Down | KeyCode::Char('j') => scroll(at + 1),
            KeyCode::PageUp => scroll(at.saturating_sub(PLAN_PAGE)),
            KeyCode::PageDown => scroll(at + PLAN_PAGE),
            KeyCode::Home | KeyCode::Char('g') => scroll(0),
            KeyCode::End | KeyCode::Char('G') => scroll(last),
            KeyCode::Char('f') => self.plan_follow = true,
            KeyCode::Char('r') => {
                let running = self.snap.as_ref().is_some_and(|s| s.stats.running);
                return self.connected().then_some(if running {
                    Command::Stop
                } else {
                    Command::Run
                });
            }
            KeyCode::Char('s') => return self.connected().then_some(Command::Step),
            _ => {}
        }
        None
    }

    fn on_prompt_key(&mut self, code: KeyCode) -> Option<Command> {
        let prompt = self.prompt.as_mut()?;
        let text = match prompt {
            Prompt::Param { text, .. } | Prompt::Priority { text, .. } => text,
        };
        match code {
            KeyCode::Esc => {
                self.prompt = None;
                self.ok("cancelled");
                None
            }
            KeyCode::Backspace => {
                text.pop();
                None
            }
            KeyCode::Char(c) if text.len() < 64 => {
                text.push(c);
                None
            }
            KeyCode::Enter => match self.prompt.take()? {
                Prompt::Param { skill, param, text } => self
                    .connected()
                    .then_some(Command::SetParam(skill, param, text.trim().to_string())),
                Prompt::Priority { skill, text } => match text.trim().parse::<i32>() {
                    Ok(p) => self.connected().then_some(Command::Priority(skill, p)),
                    Err(_) => {
                        self.err(format!(
                            "priority must be an integer, got '{}'",
                            text.trim()
                        ));
                        None
                    }
                },
            },
            _ => None,
        }
    }
}
