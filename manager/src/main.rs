//! `skillfab-manager`: a domain's skill manager (`manager`) or a manager with a launch file's
//! supervised processes (`up`). `skillfab manager …` and `skillfab up …` run this binary with
//! the same arguments, so the manager's process links neither the console nor the demo.

use clap::{Parser, Subcommand};
use skillfab_manager::args::{DomainArg, ManagerArgs, UpArgs, init_tracing, run_manager, run_up};
use skillfab_proto::domain::Domain;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "skillfab-manager",
    version,
    about = "The skillfab skill manager"
)]
struct Cli {
    #[command(flatten)]
    domain: DomainArg,
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

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_tracing();
    let result = Domain::new(&cli.domain.domain)
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
