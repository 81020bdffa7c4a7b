//! How a demo run is followed and judged: the plan's steps as its runner logs them, and the
//! simulator's ground truth read by the judge (in lock-step at holds of its own, so what it
//! sees and does falls in the same cycle every run).

use super::{RunOutcome, Site, latest};
use denning_sim::truth::TruthRecord;
use skillfab_client::Client;
use skillfab_proto::control::EventKind;
use std::path::Path;
use std::time::{Duration, Instant};

/// The steps the plan's runners printed into `up`'s log (`[cycle N, t = …] what`), read as
/// the log grows: what, cycle, the robot's time (a cycle is 10 ms of it); and how the plan
/// ended, if it has.
#[derive(Debug, Default)]
pub(super) struct StepLog {
    pub(super) steps: Vec<(String, u64, f64)>,
    pub(super) ended: Option<String>,
    /// Bytes of the log read so far (up to the last whole line).
    read: u64,
}

impl StepLog {
    /// Reads what the log gained since the last call; prints the new steps with `verbose`.
    pub(super) fn read(&mut self, log: &Path, verbose: bool) {
        use std::io::{Read, Seek, SeekFrom};
        let mut text = String::new();
        let Ok(mut f) = std::fs::File::open(log) else {
            return;
        };
        if f.seek(SeekFrom::Start(self.read)).is_err() || f.read_to_string(&mut text).is_err() {
            return;
        }
        // A line still being written is read next time.
        let whole = text.rfind('\n').map_or(0, |i| i + 1);
        self.read += whole as u64;
        for line in text[..whole].lines() {
            if let Some(rest) = line.strip_prefix("[cycle")
                && let Some((head, what)) = rest.split_once("] ")
                && let Some(Ok(cycle)) = head.split(',').next().map(|c| c.trim().parse::<u64>())
            {
                // The robot's time: a cycle is 10 ms of it (the runner prints the fabric's,
                // which a time factor scales).
                let t = cycle as f64 * 0.01;
                if verbose {
                    println!("  [cycle {cycle:>6}, t = {t:>6.1} s] {what}");
                }
                self.steps.push((what.to_string(), cycle, t));
            } else if line == "the plan succeeded" {
                self.ended = Some("Success".to_string());
            } else if line.ends_with("the plan failed") {
                self.ended = Some("Failure".to_string());
            }
        }
    }
}

/// How long a run waits for the simulator's first ground truth.
pub(super) const NO_TRUTH: Duration = Duration::from_secs(30);

/// How a run ended, by the simulator's ground truth.
#[derive(Debug, Clone, Copy)]
pub(super) enum Verdict {
    /// The robot is outside the lab (exit-lab).
    Outside,
    /// The message was delivered (deliver).
    Delivered,
    /// The message was delivered, and the plan ended with the robot back at the lab (deliver
    /// `--and-back`).
    Back,
    /// The time limit passed.
    Limit,
}

/// How the run at `site` ended by ground truth `now`, if it has. With `and_back` the message
/// delivered does not end it: the plan's end does ([`judge_back`]).
pub(super) fn judge_truth(
    site: &Site,
    now: &TruthRecord,
    limit_s: f64,
    and_back: bool,
) -> Option<Verdict> {
    if matches!(site, Site::World(_)) && now.outside {
        Some(Verdict::Outside)
    } else if now.delivered && !and_back {
        Some(Verdict::Delivered)
    } else if now.t > limit_s {
        Some(Verdict::Limit)
    } else {
        None
    }
}

/// A round trip's verdict once its plan `ended` (its runner's last line), by ground truth
/// `now`, a record after the end: back only when the plan succeeded, the message was
/// delivered and the robot is back at the lab (the simulator's `at_lab`).
pub(super) fn judge_back(ended: Option<&str>, now: &TruthRecord) -> Option<Verdict> {
    (ended == Some("Success") && now.delivered && now.at_lab).then_some(Verdict::Back)
}

/// The first ground-truth record a status period after `then`, or `then` if none comes
/// within 10 s. In lock-step the fabric (paused where the plan ended) runs two status periods
/// on to the judge's hold: the record is the same every run.
pub(super) fn truth_after(
    c: &mut Client,
    traj: &Path,
    then: TruthRecord,
    judge: Option<&mut Judge>,
) -> anyhow::Result<TruthRecord> {
    if let Some(j) = judge {
        let at = c.stats()?.cycles + 2 * JUDGE_EVERY;
        j.hold_at(c, at)?;
        c.run()?;
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            let ev = c.next_event(Duration::from_millis(100))?;
            if j.reached(c, ev.map(|e| e.kind).as_ref())? {
                return Ok(latest(traj).unwrap_or(then));
            }
        }
        return Ok(then);
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        if let Some(now) = latest(traj).filter(|r| r.t > then.t + 0.15) {
            return Ok(now);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(then)
}

/// How often (cycles) the lock-step judge looks at the ground truth: the simulator's status
/// period (100 ms of the robot's time), the rate it writes a record at.
const JUDGE_EVERY: u64 = 10;

/// The lock-step judge: it holds the fabric every [`JUDGE_EVERY`] cycles (`Client::hold`),
/// reads the ground truth there and acts on it before it lets the fabric on, so what it sees
/// and does falls in the same cycle every run. (`up --held` keeps the fabric before its first
/// cycle until the judge's first hold, even when a plan runner resumed it.)
pub(super) struct Judge {
    at: u64,
}

impl Judge {
    pub(super) fn start(c: &Client) -> anyhow::Result<Judge> {
        c.hold(Some(JUDGE_EVERY))?;
        Ok(Judge { at: JUDGE_EVERY })
    }

    fn hold_at(&mut self, c: &Client, at: u64) -> anyhow::Result<()> {
        self.at = at;
        c.hold(Some(at))?;
        Ok(())
    }

    /// Lets the fabric on to the next hold.
    pub(super) fn next(&mut self, c: &Client) -> anyhow::Result<()> {
        self.hold_at(c, self.at + JUDGE_EVERY)
    }

    /// Whether the fabric stands at the hold: told by the event `ev`, or when no event came
    /// (one may be lost to a full queue) by its cycle count: it cannot run past the hold.
    pub(super) fn reached(&self, c: &Client, ev: Option<&EventKind>) -> anyhow::Result<bool> {
        Ok(match ev {
            Some(EventKind::Held { cycle }) => *cycle >= self.at,
            Some(_) => false,
            None => c.stats()?.cycles >= self.at,
        })
    }
}

pub(super) const NO_TRUTH_ERROR: &str =
    "the simulator wrote no ground truth within 30 s (see the log of skillfab up)";

/// Acts on how the run ended: outside, the robot is stopped.
pub(super) fn verdict(
    c: &Client,
    out: &mut RunOutcome,
    v: Verdict,
    step: &dyn Fn(&Client, &mut RunOutcome, &str),
) -> anyhow::Result<()> {
    match v {
        Verdict::Outside => {
            out.success = true;
            c.activate(&["stop"])?;
            step(c, out, "outside the lab: stop");
        }
        Verdict::Delivered => {
            out.success = true;
            c.activate(&["stop"])?;
            step(c, out, "the message is delivered: stop");
        }
        Verdict::Back => {
            out.success = true;
            c.activate(&["stop"])?;
            step(c, out, "delivered, and back at the lab: stop");
        }
        Verdict::Limit => step(c, out, "time limit reached"),
    }
    Ok(())
}
