//! `skillfab-manager`: a domain's skill manager (`manager`) or a manager with a launch file's
//! supervised processes (`up`). `skillfab manager …` and `skillfab up …` run this binary with
//! the same arguments, so the manager's process links neither the console nor the demo.

use clap::{Parser, Subcommand};
use skillfab_manager::args::{ManagerArgs, UpArgs, run_manager, run_up};
use skillfab_proto::domain::{DOMAIN_ENV, Domain};
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "skillfab-manager",
    version,
    about = "The skillfab skill manager"
)]
struct Cli {
    /// Fabric domain: processes of different domains never see each other.
    #[arg(long, global = true, env = DOMAIN_ENV, default_value = "default")]
    domain: String,
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Run the skill manager of a domain.
    Manager(ManagerArgs),
    /// Start a manager and the processes of a launch file; supervise them.
    Up(UpArgs),
}

fn init_tracing() {
    use std::io::IsTerminal;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .try_init();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_tracing();
    let result = Domain::new(&cli.domain)
        .map_err(anyhow::Error::from)
        .and_then(|domain| match cli.command {
            Cmd::Manager(args) => run_manager(domain, args),
            Cmd::Up(args) => run_up(domain, args),
        });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the refusal (and its cause chain) for scripts and people alike.
            eprintln!("skillfab: error: {}", format!("{e:#}").replace('\n', " "));
            ExitCode::FAILURE
        }
    }
}
