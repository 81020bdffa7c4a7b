//! `monitor`, `unmonitor`: conditions on live outputs, evaluated every cycle.

use super::*;
use crate::checks::{check_numeric, read_as_number};
use crate::monitors::Resolved;
use crate::monitors::expr;
use skillfab_proto::control::MonitorMode;

impl Manager {
    /// Parses and type-checks a monitor expression against the outputs it reads; installs it.
    pub(crate) fn add_monitor(
        &mut self,
        client: &str,
        expr: String,
        mode: MonitorMode,
        hold: u32,
    ) -> Response {
        let parsed = expr::parse(&expr).map_err(|error| ControlError::BadExpression {
            expr: skillfab_proto::control::shorten(&expr, 120),
            error,
        })?;
        let mut paths = Vec::new();
        for p in expr::paths(&parsed) {
            let aggregate = !read_as_number(&parsed, p);
            let (topic, field, slot) = self.resolve_path(&p.skill, &p.output, &p.field, &p.text)?;
            check_numeric(&field, aggregate).map_err(|error| ControlError::BadPath {
                path: p.text.clone(),
                error,
            })?;
            self.open_reader(&p.skill, &p.output)?;
            paths.push(Resolved {
                path: p.clone(),
                topic,
                field,
                slot,
            });
        }
        let id = self
            .monitors
            .install(client, expr, parsed, mode, hold, paths);
        Ok(Reply::MonitorAdded(id))
    }

    /// Hands monitors over to `client` (a restarted plan runner taking its predecessor's):
    /// what became of each.
    pub(super) fn adopt_monitors(&mut self, client: &str, ids: &[u64]) -> Response {
        Ok(Reply::Adopted(self.monitors.adopt(client, ids)))
    }

    /// Removes one of the monitors.
    pub(super) fn remove_monitor(&mut self, id: u64) -> Response {
        if !self.monitors.remove(id) {
            return Err(ControlError::UnknownMonitor(id));
        }
        Ok(Reply::Done)
    }
}
