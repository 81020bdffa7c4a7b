//! Drawing the console: `render(&App, &mut Frame)`, nothing else. Every size is worked out
//! from the frame, so any terminal size (and a resize) just draws again.

use super::app::{App, Dir, Link, Pane, PlanView, Prompt};
use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Borders, Cell, Paragraph, Row, Sparkline, Table, TableState};
use skillfab_proto::control::{NodeStatus, SkillInfo, SkillState};
use skillfab_proto::log::Level;
use skillfab_proto::value::Value;

const BARS: [char; 8] = ['▁', '▂', '▃', '▄', '▅', '▆', '▇', '█'];

/// Arrays up to this long are printed as numbers; longer ones as a bar strip.
const SHORT_ARRAY: usize = 4;

/// A number, short: integers as they are, floats with 3 decimals (or exponent when huge/tiny).
pub fn num(x: f64) -> String {
    if !x.is_finite() {
        return "null".into();
    }
    if x == x.trunc() && x.abs() < 1e5 {
        return format!("{x:.0}");
    }
    if x.abs() >= 1e5 || x.abs() < 1e-3 {
        let short = format!("{x:e}");
        return if short.len() <= 8 {
            short
        } else {
            format!("{x:.3e}")
        };
    }
    format!("{x:.3}")
}

/// A duration in µs, as precise as is useful.
pub fn micros(x: f64) -> String {
    if x >= 10_000.0 {
        format!("{:.1} ms", x / 1000.0)
    } else if x >= 10.0 {
        format!("{x:.0} µs")
    } else {
        format!("{x:.1} µs")
    }
}

/// An array of numbers as a bar strip scaled from 0 (or the minimum, if negative) to the
/// maximum, followed by the range: `▁▁▃█▇▂ 0.41..9.80`.
pub fn bar_strip(xs: &[f64]) -> String {
    let finite: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
    let (Some(lo), Some(hi)) = (
        finite.iter().copied().reduce(f64::min),
        finite.iter().copied().reduce(f64::max),
    ) else {
        return format!("[{} × null]", xs.len());
    };
    let base = lo.min(0.0);
    let span = hi - base;
    let strip: String = xs
        .iter()
        .map(|&x| {
            if !x.is_finite() {
                return '·';
            }
            let f = if span > 0.0 { (x - base) / span } else { 0.0 };
            BARS[((f * 7.0).round() as usize).min(7)]
        })
        .collect();
    format!("{strip} {}..{}", num(lo), num(hi))
}

/// A value on one line, compactly: numbers short, long numeric arrays as a bar strip,
/// structs as `a=1 b=2`.
pub fn compact(v: &Value) -> String {
    match v {
        Value::Float(x) => num(*x),
        Value::Int(i) => i.to_string(),
        Value::UInt(u) => u.to_string(),
        Value::Bool(b) => b.to_string(),
        Value::Text(t) => format!("{t:?}"),
        Value::Null => "null".into(),
        Value::Array(items) => {
            let numbers: Option<Vec<f64>> = items.iter().map(Value::as_f64).collect();
            match numbers {
                Some(xs) if xs.len() > SHORT_ARRAY => bar_strip(&xs),
                _ => format!(
                    "[{}]",
                    items.iter().map(compact).collect::<Vec<_>>().join(", ")
                ),
            }
        }
        Value::Struct(fields) => fields
            .iter()
            .map(|(k, x)| format!("{k}={}", compact(x)))
            .collect::<Vec<_>>()
            .join(" "),
    }
}

/// A message as lines `field  value` (one per top-level field).
pub fn field_lines(v: &Value) -> Vec<(String, String)> {
    match v {
        Value::Struct(fields) => fields
            .iter()
            .map(|(k, x)| (k.clone(), compact(x)))
            .collect(),
        other => vec![(String::new(), compact(other))],
    }
}

fn dim() -> Style {
    Style::default().fg(Color::DarkGray)
}

fn state_style(state: SkillState) -> Style {
    match state {
        SkillState::Active => Style::default().fg(Color::Green),
        SkillState::Starting => Style::default().fg(Color::Yellow),
        SkillState::Inactive => dim(),
    }
}

/// Draws the whole console.
pub fn render(app: &App, f: &mut Frame) {
    let area = f.area();
    if app.pane == Pane::Plan {
        let [bar, spark, plan, status, help] = Layout::vertical([
            Constraint::Length(1),
            Constraint::Length(2),
            Constraint::Min(3),
            Constraint::Length(1),
            Constraint::Length(1),
        ])
        .areas(area);
        manager_bar(app, f, bar);
        latency(app, f, spark);
        plan_pane(app, f, plan);
        status_line(app, f, status);
        help_line(app, f, help);
        return;
    }
    let n = app.skills().len() as u16;
    let [bar, spark, table, channels, detail, status, help] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Length(2),
        Constraint::Length((n + 3).clamp(4, (area.height / 3).max(4))),
        Constraint::Length(1),
        Constraint::Min(6),
        Constraint::Length(1),
        Constraint::Length(1),
    ])
    .areas(area);
    manager_bar(app, f, bar);
    latency(app, f, spark);
    skills_table(app, f, table);
    channel_line(app, f, channels);
    detail_pane(app, f, detail);
    status_line(app, f, status);
    help_line(app, f, help);
}

fn manager_bar(app: &App, f: &mut Frame, area: Rect) {
    let mut spans = vec![
        Span::styled(" skillfab ", Style::default().add_modifier(Modifier::BOLD)),
        Span::raw(format!("· domain {} · ", app.domain)),
    ];
    match (&app.link, &app.snap) {
        (Link::Up, Some(s)) => {
            let st = &s.stats;
            spans.push(if st.running {
                Span::styled("running", Style::default().fg(Color::Green))
            } else {
                Span::styled("stopped", Style::default().fg(Color::Yellow))
            });
            let deaths = if st.deaths > 0 {
                format!(" · deaths {}", st.deaths)
            } else {
                String::new()
            };
            let late = if st.late_starts > 0 {
                format!(" · late starts {}", st.late_starts)
            } else {
                String::new()
            };
            spans.push(Span::raw(format!(
                " · cycle {} · overruns {}{late}{deaths} · latency p50 {} p99 {} max {}",
                st.cycles,
                st.overruns,
                micros(st.latency_us.p50),
                micros(st.latency_us.p99),
                micros(st.latency_us.max)
            )));
        }
        (Link::Down(why), _) => spans.push(Span::styled(
            format!("no manager ({why}); retrying"),
            Style::default().fg(Color::Red),
        )),
        (Link::Up, None) => spans.push(Span::raw("connected")),
    }
    f.render_widget(Paragraph::new(Line::from(spans)), area);
}

fn latency(app: &App, f: &mut Frame, area: Rect) {
    let [label, chart] =
        Layout::horizontal([Constraint::Length(18), Constraint::Min(1)]).areas(area);
    let lat = app
        .snap
        .as_ref()
        .filter(|_| app.link == Link::Up)
        .map_or(&[][..], |s| s.latencies.as_slice());
    let width = chart.width as usize;
    let shown = &lat[lat.len().saturating_sub(width)..];
    // Drawn from the window's minimum up, so the variation shows; the label gives the range.
    let lo = shown.iter().copied().reduce(f32::min).unwrap_or(0.0);
    let hi = shown.iter().copied().reduce(f32::max).unwrap_or(0.0);
    let range = if shown.is_empty() {
        "-".to_string()
    } else {
        format!(
            "{}..{}",
            micros(f64::from(lo)).trim_end_matches(" µs"),
            micros(f64::from(hi))
        )
    };
    f.render_widget(
        Paragraph::new(vec![
            Line::from(" cycle latency"),
            Line::styled(format!(" {range}"), dim()),
        ]),
        label,
    );
    let data: Vec<u64> = shown
        .iter()
        .map(|&x| ((x - lo) * 10.0).round() as u64 + 1)
        .collect();
    f.render_widget(
        Sparkline::default()
            .data(&data)
            .style(Style::default().fg(Color::Cyan)),
        chart,
    );
}

fn age(s: &SkillInfo, cycle: u64) -> String {
    if s.figures.last_cycle == 0 {
        "-".into()
    } else {
        format!("{} cyc", cycle.saturating_sub(s.figures.last_cycle))
    }
}

/// A skill's deadline misses; any is shown in red.
fn late_cell(misses: u64) -> Cell<'static> {
    let cell = Cell::from(misses.to_string());
    if misses > 0 {
        cell.style(Style::default().fg(Color::Red))
    } else {
        cell
    }
}

/// A skill's allocations on the cycle's path after warm-up (`-`: not counted); any is shown
/// in yellow.
fn allocs_cell(allocs: Option<u64>) -> Cell<'static> {
    match allocs {
        None => Cell::from("-").style(dim()),
        Some(0) => Cell::from("0"),
        Some(n) => Cell::from(n.to_string()).style(Style::default().fg(Color::Yellow)),
    }
}

fn skills_table(app: &App, f: &mut Frame, area: Rect) {
    let cycle = app.snap.as_ref().map_or(0, |s| s.stats.cycles);
    let header = Row::new(
        [
            "skill", "kind", "mode", "state", "prio", "runs", "fails", "compute", "late", "allocs",
            "last out", "log",
        ]
        .map(|h| Cell::from(h).style(Style::default().add_modifier(Modifier::BOLD))),
    );
    let rows: Vec<Row> = app
        .skills()
        .iter()
        .map(|s| {
            Row::new(vec![
                Cell::from(s.name.clone()),
                Cell::from(s.kind.clone()),
                Cell::from(s.mode.to_string()),
                Cell::from(s.state.as_str()).style(state_style(s.state)),
                Cell::from(s.priority.to_string()),
                Cell::from(s.figures.runs.to_string()),
                Cell::from(s.figures.failures.to_string()),
                Cell::from(micros(s.figures.compute_us_mean)),
                late_cell(s.figures.deadline_misses),
                allocs_cell(s.figures.cycle_allocs),
                Cell::from(age(s, cycle)),
                Cell::from(if app.io_logged(&s.name) { "io" } else { "" }),
            ])
        })
        .collect();
    let widths = [
        Constraint::Min(12),
        Constraint::Min(10),
        Constraint::Length(5),
        Constraint::Length(8),
        Constraint::Length(4),
        Constraint::Length(8),
        Constraint::Length(5),
        Constraint::Length(10),
        Constraint::Length(5),
        Constraint::Length(6),
        Constraint::Length(9),
        Constraint::Length(3),
    ];
    let title = if app.link == Link::Up {
        format!(" skills ({}) ", app.skills().len())
    } else {
        " skills (last known) ".into()
    };
    let table = Table::new(rows, widths)
        .header(header)
        .block(Block::default().borders(Borders::ALL).title(title))
        .row_highlight_style(Style::default().add_modifier(Modifier::REVERSED))
        .highlight_symbol("▶ ");
    let mut state = TableState::default();
    if !app.skills().is_empty() {
        state.select(Some(app.selected));
    }
    f.render_stateful_widget(table, area, &mut state);
}

fn channel_line(app: &App, f: &mut Frame, area: Rect) {
    let text = match &app.snap {
        Some(s) if !s.stats.channels.is_empty() => {
            let parts: Vec<String> = s
                .stats
                .channels
                .iter()
                .map(|c| format!("{} → {} (cycle {})", c.channel, c.winner, c.cycle))
                .collect();
            format!(" channels: {}", parts.join(" · "))
        }
        _ => " channels: none".into(),
    };
    f.render_widget(Paragraph::new(text), area);
}

fn detail_pane(app: &App, f: &mut Frame, area: Rect) {
    let Some(s) = app.selected_skill() else {
        let text = match &app.link {
            Link::Down(_) => {
                "waiting for the manager of this domain (skillfab up / skillfab manager)"
            }
            Link::Up => "no skills registered",
        };
        f.render_widget(
            Paragraph::new(text)
                .style(dim())
                .block(Block::default().borders(Borders::ALL).title(" detail ")),
            area,
        );
        return;
    };
    let title = format!(
        " {} · {} {} · {} · priority {} · pid {} · compute last {} ",
        s.name,
        s.mode,
        s.kind,
        s.state,
        s.priority,
        s.pid,
        micros(s.figures.compute_us_last)
    );
    let block = Block::default().borders(Borders::ALL).title(title);
    let inner = block.inner(area);
    f.render_widget(block, area);
    let [top, logs] =
        Layout::vertical([Constraint::Percentage(60), Constraint::Percentage(40)]).areas(inner);
    let [io, params] =
        Layout::horizontal([Constraint::Percentage(62), Constraint::Percentage(38)]).areas(top);
    io_lines(app, s, f, io);
    param_lines(app, s, f, params);
    log_lines(app, f, logs);
}

fn io_lines(app: &App, s: &SkillInfo, f: &mut Frame, area: Rect) {
    let mut lines = Vec::new();
    let ports = app.ports();
    if ports.is_empty() && !(s.inputs.is_empty() && s.outputs.is_empty()) {
        lines.push(Line::styled("reading ports…", dim()));
    }
    for p in ports {
        let arrow = match p.dir {
            Dir::In => "in ",
            Dir::Out => "out",
        };
        let (at, fields) = match &p.value {
            Ok((v, cycle)) => (format!("cycle {cycle}"), field_lines(v)),
            Err(e) => (e.clone(), Vec::new()),
        };
        lines.push(Line::from(vec![
            Span::styled(
                format!("{arrow} {}", p.port),
                Style::default().add_modifier(Modifier::BOLD),
            ),
            Span::styled(
                format!(
                    " {} {} {} · {at}",
                    p.type_name,
                    if p.dir == Dir::In { "←" } else { "→" },
                    p.source
                ),
                dim(),
            ),
        ]));
        for (k, v) in fields {
            lines.push(Line::from(format!("    {k:<10} {v}")));
        }
    }
    f.render_widget(Paragraph::new(lines), area);
}

fn param_lines(app: &App, s: &SkillInfo, f: &mut Frame, area: Rect) {
    let mut lines = vec![Line::styled(
        "params (tab: next, e: edit)",
        Style::default().add_modifier(Modifier::BOLD),
    )];
    if s.params.is_empty() {
        lines.push(Line::styled("none", dim()));
    }
    let width = s.params.iter().map(|p| p.name.len()).max().unwrap_or(0);
    for (i, p) in s.params.iter().enumerate() {
        let value = s
            .values
            .iter()
            .find(|(n, _)| *n == p.name)
            .map_or(p.default, |(_, v)| *v);
        let b = |v: &Option<skillfab_proto::param::ParamValue>| v.map(|v| num(v.as_f64()));
        let bounds = match (b(&p.min), b(&p.max)) {
            (Some(lo), Some(hi)) => format!("[{lo}, {hi}]"),
            (Some(lo), None) => format!("[{lo}, ∞)"),
            (None, Some(hi)) => format!("(-∞, {hi}]"),
            (None, None) => String::new(),
        };
        let style = if i == app.param {
            Style::default().add_modifier(Modifier::REVERSED)
        } else {
            Style::default()
        };
        lines.push(Line::from(vec![
            Span::styled(
                format!("{:<width$} {:>7}", p.name, value.to_string()),
                style,
            ),
            Span::styled(format!(" {} {bounds}", p.kind), dim()),
        ]));
    }
    f.render_widget(Paragraph::new(lines), area);
}

fn log_lines(app: &App, f: &mut Frame, area: Rect) {
    let title = if app.verbose {
        " log (verbose: all levels; v: warnings only) "
    } else {
        " log (warnings and errors; v: verbose) "
    };
    let block = Block::default().borders(Borders::TOP).title(title);
    let inner = block.inner(area);
    f.render_widget(block, area);
    let shown: Vec<_> = app.skill_logs().collect();
    let take = inner.height as usize;
    let lines: Vec<Line> = if shown.is_empty() {
        vec![Line::styled("no lines", dim())]
    } else {
        shown[shown.len().saturating_sub(take)..]
            .iter()
            .map(|l| {
                let color = match l.level {
                    Level::Error => Color::Red,
                    Level::Warn => Color::Yellow,
                    Level::Info => Color::Reset,
                    _ => Color::DarkGray,
                };
                let mut text = format!("{:<5} {}", l.level, l.message);
                if l.dropped > 0 {
                    text.push_str(&format!(" (+{} dropped)", l.dropped));
                }
                Line::styled(text, Style::default().fg(color))
            })
            .collect()
    };
    f.render_widget(Paragraph::new(lines), inner);
}

fn status_line(app: &App, f: &mut Frame, area: Rect) {
    let line = match (&app.prompt, &app.status) {
        (Some(Prompt::Param { skill, param, text }), _) => Line::from(vec![
            Span::styled(
                format!(" set {skill}.{param} = "),
                Style::default().fg(Color::Cyan),
            ),
            Span::raw(format!("{text}▏")),
            Span::styled("  (enter: apply, esc: cancel)", dim()),
        ]),
        (Some(Prompt::Priority { skill, text }), _) => Line::from(vec![
            Span::styled(
                format!(" priority of {skill} = "),
                Style::default().fg(Color::Cyan),
            ),
            Span::raw(format!("{text}▏")),
            Span::styled("  (enter: apply, esc: cancel)", dim()),
        ]),
        (None, Some((true, e))) => {
            Line::styled(format!(" error: {e}"), Style::default().fg(Color::Red))
        }
        (None, Some((false, m))) => {
            Line::styled(format!(" {m}"), Style::default().fg(Color::Green))
        }
        (None, None) => {
            let file = app
                .snap
                .as_ref()
                .and_then(|s| s.log_file.clone())
                .map_or(String::new(), |p| format!(" fabric log: {p}"));
            Line::styled(file, dim())
        }
    };
    f.render_widget(Paragraph::new(line), area);
}

/// A node status's colour: idle grey, running yellow, success green, failure red.
fn status_style(s: NodeStatus) -> Style {
    match s {
        NodeStatus::Idle => dim(),
        NodeStatus::Running => Style::default().fg(Color::Yellow),
        NodeStatus::Success => Style::default().fg(Color::Green),
        NodeStatus::Failure => Style::default().fg(Color::Red),
    }
}

/// The first node shown: where the user scrolled to, or (following) so that the deepest
/// running node is in the upper third of the pane.
pub fn plan_first_line(app: &App, plan: &PlanView, height: usize) -> usize {
    let n = plan.tree.nodes.len();
    let first = if app.plan_follow {
        app.plan_anchor().saturating_sub(height / 3)
    } else {
        app.plan_scroll
    };
    first.min(n.saturating_sub(height))
}

/// The plan as a tree, every node (no cap): indented by depth, its status as a coloured
/// letter, the branch that runs highlighted, the cycle of its last change.
fn plan_pane(app: &App, f: &mut Frame, area: Rect) {
    let Some(plan) = &app.plan else {
        f.render_widget(
            Paragraph::new("no plan has run since the console connected (skillfab sequence FILE)")
                .style(dim())
                .block(Block::default().borders(Borders::ALL).title(" plan ")),
            area,
        );
        return;
    };
    let t = &plan.tree;
    let branch = t.running_branch();
    let depths = t.depths();
    let mut parent = vec![false; t.nodes.len()];
    for p in t.nodes.iter().filter_map(|n| n.parent) {
        if let Some(x) = parent.get_mut(p as usize) {
            *x = true;
        }
    }
    // The running leaves: where the plan is.
    let running: Vec<&str> = t
        .nodes
        .iter()
        .filter(|n| t.status[n.id as usize].0 == NodeStatus::Running && !parent[n.id as usize])
        .map(|n| n.name.as_str())
        .collect();
    let state = match plan.ended {
        Some(s) => format!("ended: {s}"),
        None if running.is_empty() => "running".to_string(),
        None => format!("at {}", running.join(", ")),
    };
    let title = format!(" plan {} · {} nodes · {state} ", t.plan, t.nodes.len());
    let block = Block::default().borders(Borders::ALL).title(title);
    let inner = block.inner(area);
    f.render_widget(block, area);
    let height = inner.height as usize;
    let first = plan_first_line(app, plan, height);
    let lines: Vec<Line> = t
        .nodes
        .iter()
        .skip(first)
        .take(height)
        .map(|n| {
            let i = n.id as usize;
            let (status, since) = t.status[i];
            let on = branch[i];
            let name_style = if on {
                Style::default()
                    .fg(Color::Yellow)
                    .add_modifier(Modifier::BOLD)
            } else if status == NodeStatus::Idle {
                dim()
            } else {
                Style::default()
            };
            let mut spans = vec![
                Span::styled(if on { "▶" } else { " " }, name_style),
                Span::raw(" ".repeat(1 + 2 * depths[i])),
                Span::styled(
                    status.letter().to_string(),
                    status_style(status).add_modifier(Modifier::BOLD),
                ),
                Span::raw(" "),
                Span::styled(n.name.clone(), name_style),
            ];
            if n.kind != n.name {
                spans.push(Span::styled(format!(" {}", n.kind), dim()));
            }
            if !n.detail.is_empty() {
                spans.push(Span::styled(format!(" · {}", n.detail), dim()));
            }
            if status != NodeStatus::Idle {
                spans.push(Span::styled(format!(" · cycle {since}"), dim()));
            }
            Line::from(spans)
        })
        .collect();
    f.render_widget(Paragraph::new(lines), inner);
}

fn help_line(app: &App, f: &mut Frame, area: Rect) {
    let skills_keys = [
        ("↑↓/jk", "select"),
        ("a", "(de)activate"),
        ("tab/e", "param"),
        ("p", "prio"),
        ("l", "io log"),
        ("v", "verbose"),
        ("t", "plan"),
        ("r", "run/stop"),
        ("s", "step"),
        ("q", "quit"),
    ];
    let plan_keys = [
        ("↑↓/jk", "scroll"),
        ("PgUp/PgDn", "page"),
        ("g/G", "top/end"),
        ("f", "follow"),
        ("t", "skills"),
        ("r", "run/stop"),
        ("s", "step"),
        ("q", "quit"),
    ];
    let keys: &[(&str, &str)] = match app.pane {
        Pane::Skills => &skills_keys,
        Pane::Plan => &plan_keys,
    };
    let mut spans = vec![Span::raw(" ")];
    for &(k, what) in keys {
        spans.push(Span::styled(
            k,
            Style::default()
                .fg(Color::Black)
                .bg(Color::Gray)
                .add_modifier(Modifier::BOLD),
        ));
        spans.push(Span::raw(format!(" {what}  ")));
    }
    f.render_widget(Paragraph::new(Line::from(spans)), area);
}
