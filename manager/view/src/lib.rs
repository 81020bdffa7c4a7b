//! `skillfab view`: the running fabric live in Foxglove (or any client of the Foxglove
//! WebSocket protocol), and an SVG snapshot of what it shows.
//!
//! ## Layout
//! - [`protocol`]: the protocol's messages (`foxglove.websocket.v1`), parsed and built;
//! - [`conn`]: one thread per viewer — handshake, reads, writes of its bounded outbox;
//! - [`hub`]: the one thread on the fabric's side — topics, events, logs, parameters,
//!   services; it never waits for a viewer;
//! - [`scene`]: the world (or building) and the robot as `foxglove.SceneUpdate`s;
//! - [`snapshot`]: one moment of what a viewer is sent, drawn as SVG (`--snapshot`).
//!
//! The view is an external reader of the fabric: it reads topics as `ctl echo` does, never
//! registers as a skill, and the manager answers its requests between cycles like any other
//! client's. A viewer that reads slowly loses message frames (counted, and told), never a
//! cycle.

#![warn(missing_docs)]

pub mod conn;
pub mod hub;
pub mod protocol;
pub mod scene;
pub mod snapshot;

use hub::{FromViewer, Hub, HubOptions};
use scene::Scene;
use skillfab_proto::domain::Domain;
use std::net::TcpListener;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::channel;
use std::time::Duration;

/// `skillfab view` options.
#[derive(clap::Args, Debug, Clone)]
pub struct ViewArgs {
    /// Address to serve on (open it in Foxglove: "Open connection", Foxglove WebSocket,
    /// `ws://HOST:PORT`).
    #[arg(long, default_value = "127.0.0.1:8765", value_name = "HOST:PORT")]
    pub listen: String,
    /// The simulator's world or building file: shown as a 3-D scene (`/scene`), and its
    /// start pose places the odometry frame in the map.
    #[arg(long, value_name = "FILE")]
    pub world: Option<PathBuf>,
    /// The simulator's ground-truth file (`denning-sim --trajectory FILE`): the robot's true
    /// pose as the `truth` frame.
    #[arg(long, value_name = "FILE")]
    pub truth: Option<PathBuf>,
    /// At most this many messages a second per channel to every viewer (a viewer may ask for
    /// its own with `ws://HOST:PORT/?max_hz=N`); default: every sample.
    #[arg(long, value_name = "HZ")]
    pub max_hz: Option<f64>,
    /// Viewers served at once; more are refused (HTTP 503).
    #[arg(long, default_value_t = 64)]
    pub max_viewers: usize,
    /// Write one moment of the scene to this SVG file and exit (no server).
    #[arg(long, value_name = "FILE.svg")]
    pub snapshot: Option<PathBuf>,
}

/// What stops the view from starting.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The world file.
    #[error(transparent)]
    Scene(#[from] scene::SceneError),
    /// The address.
    #[error("cannot listen on {addr}: {source}")]
    Listen {
        /// The address.
        addr: String,
        /// Why.
        source: std::io::Error,
    },
    /// The fabric.
    #[error(transparent)]
    Fabric(#[from] skillfab_proto::Error),
    /// `--max-hz`.
    #[error("--max-hz {0}: not a positive number")]
    Rate(f64),
    /// The snapshot.
    #[error(transparent)]
    Snapshot(#[from] snapshot::SnapshotError),
}

/// Serves the domain to viewers until SIGINT or SIGTERM (or writes a snapshot and returns,
/// with `--snapshot`). `ready` is called with the address served once it listens.
pub fn run(domain: &Domain, args: &ViewArgs, ready: &dyn Fn(&str)) -> Result<(), ViewError> {
    if let Some(hz) = args.max_hz.filter(|h| !(*h > 0.0 && h.is_finite())) {
        return Err(ViewError::Rate(hz));
    }
    let scene = args.world.as_deref().map(Scene::load).transpose()?;
    if let Some(out) = &args.snapshot {
        return Ok(snapshot::take(domain, scene, args.truth.as_deref(), out)?);
    }
    let listener = TcpListener::bind(&args.listen).map_err(|source| ViewError::Listen {
        addr: args.listen.clone(),
        source,
    })?;
    listener
        .set_nonblocking(true)
        .map_err(|source| ViewError::Listen {
            addr: args.listen.clone(),
            source,
        })?;
    let addr = listener
        .local_addr()
        .map_or_else(|_| args.listen.clone(), |a| a.to_string());
    let stop = Arc::new(AtomicBool::new(false));
    let (to_hub, from_viewers) = channel::<FromViewer>();
    let hub_thread = Hub::spawn(
        HubOptions {
            domain: domain.clone(),
            scene,
            truth: args.truth.clone(),
            max_hz: args.max_hz,
        },
        from_viewers,
        stop.clone(),
    )?;
    tracing::info!(%addr, "serving the Foxglove WebSocket protocol");
    ready(&addr);
    let live = Arc::new(AtomicUsize::new(0));
    let mut next_id = 0u64;
    while !skillfab_proto::services::termination_requested() && !hub_thread.is_finished() {
        match listener.accept() {
            Ok((stream, _)) => {
                let _ = stream.set_nonblocking(false);
                next_id += 1;
                let full = live.load(Ordering::Relaxed) >= args.max_viewers;
                let (to_hub, stop, live) = (to_hub.clone(), stop.clone(), live.clone());
                let id = next_id;
                live.fetch_add(1, Ordering::Relaxed);
                let spawned = std::thread::Builder::new()
                    .name(format!("viewer-{id}"))
                    .spawn(move || {
                        conn::serve(stream, id, full, &to_hub, &stop);
                        live.fetch_sub(1, Ordering::Relaxed);
                    });
                if let Err(e) = spawned {
                    tracing::warn!(error = %e, "viewer thread not started");
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => tracing::warn!(error = %e, "accept failed"),
        }
    }
    stop.store(true, Ordering::Relaxed);
    drop(to_hub);
    let _ = hub_thread.join();
    Ok(())
}
