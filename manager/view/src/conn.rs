//! One viewer's connection: the WebSocket handshake, then a loop that reads what the viewer
//! sends (parsed here; bad messages answered here) and writes what the hub queued for it.
//!
//! The hub never waits for a viewer: it appends to the viewer's [`Outbox`] and goes on. The
//! outbox keeps control messages (answers, advertisements, status) whole and in order, and at
//! most [`DATA_FRAMES`] message-data frames: past that the oldest are dropped and counted, and
//! the viewer is told how many in a warning — a slow browser loses samples, never cycles.

use crate::hub::{FromViewer, ViewerId};
use crate::protocol::{self, Level, SUBPROTOCOL, ServerMessage};
use std::collections::VecDeque;
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tungstenite::http::{HeaderValue, StatusCode};
use tungstenite::{Message, WebSocket};

/// Message-data frames kept for a viewer that does not read them fast enough.
pub const DATA_FRAMES: usize = 512;
/// How long a read waits before the loop writes what was queued: the longest a queued
/// frame waits for a viewer that sends nothing.
const TICK: Duration = Duration::from_millis(10);
/// How long a write may block on a viewer that does not read before it is dropped.
const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// How often a viewer that loses frames is told how many.
const LOSS_REPORT: Duration = Duration::from_secs(1);

#[derive(Default)]
struct Queues {
    control: VecDeque<Message>,
    data: VecDeque<Vec<u8>>,
    dropped: u64,
}

/// What the hub has queued for one viewer.
#[derive(Default)]
pub struct Outbox {
    queues: Mutex<Queues>,
    closed: AtomicBool,
}

impl Outbox {
    fn with<R>(&self, f: impl FnOnce(&mut Queues) -> R) -> R {
        let mut q = self
            .queues
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        f(&mut q)
    }

    /// Queues a text message (kept whatever the queue's length).
    pub fn text(&self, m: &ServerMessage) {
        let t = m.to_text();
        self.with(|q| q.control.push_back(Message::text(t)));
    }

    /// Queues a binary control frame (a service call's answer: kept).
    pub fn binary(&self, b: Vec<u8>) {
        self.with(|q| q.control.push_back(Message::binary(b)));
    }

    /// Queues a message-data frame, dropping the oldest past [`DATA_FRAMES`].
    pub fn data(&self, frame: Vec<u8>) {
        self.with(|q| {
            if q.data.len() >= DATA_FRAMES {
                q.data.pop_front();
                q.dropped += 1;
            }
            q.data.push_back(frame);
        });
    }

    /// Whether the connection is gone (the hub stops queuing for it).
    pub fn is_closed(&self) -> bool {
        self.closed.load(Ordering::Relaxed)
    }

    /// Frames dropped so far.
    pub fn dropped(&self) -> u64 {
        self.with(|q| q.dropped)
    }

    pub(crate) fn take(&self) -> (Vec<Message>, Vec<Vec<u8>>) {
        self.with(|q| (q.control.drain(..).collect(), q.data.drain(..).collect()))
    }
}

/// What the viewer asked for in its address: `ws://host:port/?max_hz=10` throttles every
/// channel to at most 10 messages a second for this viewer.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Wishes {
    /// The most messages per second per channel (none: every sample).
    pub max_hz: Option<f64>,
}

fn wishes(uri: &str) -> Result<Wishes, String> {
    let mut w = Wishes::default();
    let Some((_, query)) = uri.split_once('?') else {
        return Ok(w);
    };
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        match pair.split_once('=') {
            Some(("max_hz", v)) => match v.parse::<f64>() {
                Ok(hz) if hz > 0.0 && hz.is_finite() => w.max_hz = Some(hz),
                _ => return Err(format!("max_hz={v}: not a positive number")),
            },
            _ => return Err(format!("unknown option {pair:?} (known: max_hz=N)")),
        }
    }
    Ok(w)
}

fn refuse(status: StatusCode, why: String) -> ErrorResponse {
    let mut r = ErrorResponse::new(Some(why));
    *r.status_mut() = status;
    r
}

/// The handshake: the viewer must offer [`SUBPROTOCOL`]; its address's options are read.
// The refusal's type is tungstenite's callback's (an HTTP response), not ours to box.
#[allow(clippy::result_large_err)]
fn handshake(stream: TcpStream, full: bool) -> Result<(WebSocket<TcpStream>, Wishes), String> {
    let mut wished = Ok(Wishes::default());
    let ws = tungstenite::accept_hdr(stream, |req: &Request, mut resp: Response| {
        if full {
            return Err(refuse(
                StatusCode::SERVICE_UNAVAILABLE,
                "the view serves no more viewers (--max-viewers)".into(),
            ));
        }
        let offered = req
            .headers()
            .get_all("Sec-WebSocket-Protocol")
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(',').map(str::trim))
            .any(|p| p == SUBPROTOCOL);
        if !offered {
            return Err(refuse(
                StatusCode::BAD_REQUEST,
                format!("offer the subprotocol {SUBPROTOCOL}"),
            ));
        }
        wished = wishes(&req.uri().to_string());
        if let Err(why) = &wished {
            return Err(refuse(StatusCode::BAD_REQUEST, why.clone()));
        }
        resp.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            HeaderValue::from_static(SUBPROTOCOL),
        );
        Ok(resp)
    })
    .map_err(|e| e.to_string())?;
    Ok((ws, wished?))
}

fn is_timeout(e: &tungstenite::Error) -> bool {
    matches!(e, tungstenite::Error::Io(io)
        if matches!(io.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut))
}

/// Serves one viewer until it leaves or `stop` is set; tells the hub it came and went.
pub fn serve(
    stream: TcpStream,
    id: ViewerId,
    full: bool,
    hub: &Sender<FromViewer>,
    stop: &AtomicBool,
) {
    let peer = stream
        .peer_addr()
        .map_or_else(|_| "?".to_string(), |a| a.to_string());
    // A viewer that never completes its handshake does not hold a thread for ever.
    let _ = stream.set_read_timeout(Some(WRITE_TIMEOUT));
    let (mut ws, wishes) = match handshake(stream, full) {
        Ok(x) => x,
        Err(why) => {
            tracing::info!(%peer, %why, "viewer refused");
            return;
        }
    };
    let _ = ws.get_mut().set_read_timeout(Some(TICK));
    let _ = ws.get_mut().set_write_timeout(Some(WRITE_TIMEOUT));
    let _ = ws.get_mut().set_nodelay(true);
    let outbox = Arc::new(Outbox::default());
    tracing::info!(%peer, viewer = id, "viewer connected");
    if hub
        .send(FromViewer::Joined {
            id,
            outbox: outbox.clone(),
            wishes,
        })
        .is_err()
    {
        return;
    }
    let mut told_dropped = 0;
    let mut last_report = Instant::now();
    let why = loop {
        if stop.load(Ordering::Relaxed) {
            let _ = ws.close(None);
            let _ = ws.flush();
            break "the view is stopping".to_string();
        }
        match ws.read() {
            Ok(Message::Text(t)) => match protocol::parse_text(&t) {
                Ok(m) => {
                    let _ = hub.send(FromViewer::Message { id, message: m });
                }
                Err(e) => outbox.text(&ServerMessage::status(Level::Error, e.to_string(), None)),
            },
            Ok(Message::Binary(b)) => match protocol::parse_binary(&b) {
                Ok(call) => {
                    let _ = hub.send(FromViewer::Call { id, call });
                }
                Err(e) => outbox.text(&ServerMessage::status(Level::Error, e.to_string(), None)),
            },
            Ok(Message::Close(_)) => break "closed by the viewer".into(),
            Ok(_) => {}
            Err(e) if is_timeout(&e) => {}
            Err(e) => break e.to_string(),
        }
        let dropped = outbox.dropped();
        if dropped > told_dropped && last_report.elapsed() >= LOSS_REPORT {
            outbox.text(&ServerMessage::status(
                Level::Warning,
                format!(
                    "{} message(s) dropped: this viewer reads slower than the fabric publishes \
                     (ask for less with ws://…/?max_hz=N)",
                    dropped - told_dropped
                ),
                None,
            ));
            told_dropped = dropped;
            last_report = Instant::now();
        }
        let (control, data) = outbox.take();
        let sent = control
            .into_iter()
            .chain(data.into_iter().map(Message::binary))
            .try_for_each(|m| ws.write(m))
            .and_then(|()| ws.flush());
        match sent {
            Ok(()) => {}
            Err(e) if is_timeout(&e) => {
                break "a write timed out (the viewer stopped reading)".into();
            }
            Err(e) => break e.to_string(),
        }
    };
    outbox.closed.store(true, Ordering::Relaxed);
    tracing::info!(%peer, viewer = id, %why, "viewer left");
    let _ = hub.send(FromViewer::Left { id });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_in_the_address_are_read_and_unknown_ones_refused() {
        assert_eq!(wishes("/"), Ok(Wishes::default()));
        assert_eq!(wishes("/?max_hz=10"), Ok(Wishes { max_hz: Some(10.0) }));
        assert!(wishes("/?max_hz=0").unwrap_err().contains("max_hz=0"));
        assert!(wishes("/?max_hz=x").is_err());
        assert!(wishes("/?speed=3").unwrap_err().contains("speed"));
    }

    #[test]
    fn a_full_outbox_drops_the_oldest_data_and_keeps_every_control_message() {
        let o = Outbox::default();
        for i in 0..(DATA_FRAMES + 3) {
            o.data(vec![(i % 256) as u8]);
        }
        o.text(&ServerMessage::status(Level::Info, "x", None));
        assert_eq!(o.dropped(), 3);
        let (control, data) = o.take();
        assert_eq!((control.len(), data.len()), (1, DATA_FRAMES));
        assert_eq!(data[0], vec![3u8]);
    }
}
