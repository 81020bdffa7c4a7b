//! The exit-lab network of `record-report` and `view-report`: simulator, Denning device,
//! wander, avoid and barcode_track active, every other standard skill registered and idle,
//! at 100 Hz in real time; and what both reports' command lines share.

use std::path::{Path, PathBuf};

/// The standard skills of the network and whether each starts active.
pub const SKILLS: [(&str, bool); 8] = [
    ("wander", true),
    ("avoid", true),
    ("barcode_track", true),
    ("wall_follow", false),
    ("home", false),
    ("door_locate", false),
    ("go_through", false),
    ("stop", false),
];

/// The launch file of the network on `world`, the robot's link at `link`.
pub fn launch(world: &Path, link: &Path) -> String {
    let mut s = format!(
        "[manager]\nperiod_ms = 10\n\
         [[process]]\nname = \"denning-sim\"\nbin = \"denning-sim\"\nregisters = false\n\
         args = [\"--world\", \"{}\", \"--link\", \"{}\", \"--seed\", \"1\"]\n\
         [[process]]\nname = \"denning\"\nbin = \"denning\"\nargs = [\"--port\", \"{}\"]\n",
        world.display(),
        link.display(),
        link.display()
    );
    for (name, active) in SKILLS {
        s.push_str(&format!(
            "[[process]]\nname = \"{name}\"\nbin = \"{name}\"\nactive = {active}\n"
        ));
    }
    s
}

/// The value after `name` on the command line.
pub fn arg_value(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

/// The world of `--world` (default: exit-lab), as an absolute path.
pub fn arg_world() -> Result<PathBuf, String> {
    let args: Vec<String> = std::env::args().collect();
    let w = arg_value(&args, "--world")
        .unwrap_or_else(|| "devices/denning-sim/worlds/exit-lab.toml".into());
    std::fs::canonicalize(&w).map_err(|e| format!("world {w}: {e}"))
}

/// A failed step's reason: `what: error`.
pub fn because<E: std::fmt::Display>(what: &str) -> impl Fn(E) -> String + '_ {
    move |e| format!("{what}: {e}")
}

/// The median (NaN of none).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}
