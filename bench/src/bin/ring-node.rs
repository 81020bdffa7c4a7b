//! A node of the benchmarks' floor rings (`skillfab_bench::floors`):
//! `ring-node iox INDEX TOPIC EVENT OUT_TOPIC OUT_EVENT SPIN_US` (in `SKILLFAB_DOMAIN`) or
//! `ring-node pipe`, or `ring-node futex INDEX NEXT SHM_NAME ring|star`.

use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["pipe"] => skillfab_bench::floors::pipe_node(),
        ["futex", index, next, name, mode] => {
            let (Ok(index), Ok(next)) = (index.parse(), next.parse()) else {
                eprintln!("ring-node: bad index {index} or next {next}");
                return ExitCode::FAILURE;
            };
            if let Err(e) = skillfab_bench::futex::futex_node(index, next, name, *mode == "star") {
                eprintln!("ring-node: futex page {name}: {e}");
                return ExitCode::FAILURE;
            }
        }
        ["iox", index, topic, event, out_topic, out_event, spin_us] => {
            let Ok(spin_us) = spin_us.parse::<u64>() else {
                eprintln!("ring-node: bad spin {spin_us}");
                return ExitCode::FAILURE;
            };
            let Ok(index) = index.parse() else {
                eprintln!("ring-node: bad index {index}");
                return ExitCode::FAILURE;
            };
            let name = std::env::var("SKILLFAB_DOMAIN").unwrap_or_else(|_| "default".into());
            let domain = match skillfab_proto::domain::Domain::new(&name) {
                Ok(d) => d,
                Err(e) => {
                    eprintln!("ring-node: {e}");
                    return ExitCode::FAILURE;
                }
            };
            let spin = std::time::Duration::from_micros(spin_us);
            skillfab_bench::floors::iox_node(
                &domain, index, topic, event, out_topic, out_event, spin,
            );
        }
        _ => {
            eprintln!(
                "usage: ring-node pipe | ring-node iox INDEX TOPIC EVENT OUT_TOPIC OUT_EVENT SPIN_US | ring-node futex INDEX NEXT SHM_NAME ring|star"
            );
            return ExitCode::FAILURE;
        }
    }
    ExitCode::SUCCESS
}
