//! `monitor`: conditions on live outputs, evaluated every cycle (removing, adopting and
//! listing them is the [`crate::monitors::Monitors`]' own bookkeeping).

use super::query::{open_reader, resolve_path};
use crate::checks::{check_numeric, read_as_number};
use crate::engine::observers::Observers;
use crate::engine::skills::Skills;
use crate::monitors::Resolved;
use crate::monitors::expr;
use iceoryx2::node::Node;
use iceoryx2::prelude::*;
use skillfab_proto::control::{ControlError, MonitorMode, Reply, Response};

/// Parses and type-checks a monitor expression against the outputs it reads; installs it,
/// evaluated from cycle `from` on (the next to start: see `Monitor::from_cycle`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn add_monitor(
    observers: &mut Observers,
    skills: &Skills,
    node: &Node<ipc::Service>,
    client: &str,
    expr: String,
    mode: MonitorMode,
    hold: u32,
    from: u64,
) -> Response {
    let parsed = expr::parse(&expr).map_err(|error| ControlError::BadExpression {
        expr: skillfab_proto::control::shorten(&expr, 120),
        error,
    })?;
    let mut paths = Vec::new();
    for p in expr::paths(&parsed) {
        let aggregate = !read_as_number(&parsed, p);
        let (topic, field, slot) = resolve_path(skills, &p.skill, &p.output, &p.field, &p.text)?;
        check_numeric(&field, aggregate).map_err(|error| ControlError::BadPath {
            path: p.text.clone(),
            error,
        })?;
        open_reader(observers, skills, node, &p.skill, &p.output)?;
        paths.push(Resolved {
            path: p.clone(),
            topic,
            field,
            slot,
        });
    }
    let id = observers
        .monitors
        .install(client, expr, parsed, mode, hold, paths, from);
    Ok(Reply::MonitorAdded(id))
}
