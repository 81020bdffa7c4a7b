//! `latency-report [--json] [--cycles N] [--repeats R] [--svg FILE] [--only SUBSTRING]`: every case of the
//! cycle benchmarks, back to back and paced at 100 Hz, with its floors measured in the same
//! run, over the same wake-ups (see `report`), repeated R times (default 3) with fabric and
//! floors interleaved; p50 / p99 / max in µs, the spread of the repeats' p50s, the round
//! trips, and the ratio skillfab ÷ iceoryx2 ring; then the idle cost against its floor.
//! `--scale [SECS]`: the scale sweep instead (chains of 1…64 skills at 100 Hz and 1 kHz;
//! `--sizes 6` and `--rates 1000` pick some, `--realtime fifo:80[@CPUS][+mlock]` runs them in
//! real-time mode, docs/realtime.md).
//! `--peer dora` / `--peer copper`: skillfab against dora-rs 1.1 (chains of 1…8) or Copper 1.2
//! (1…16) on the same chains instead.
//! `--spin-curve`: chains of 1…8 skills and exit-lab at 100 Hz with every skill's spin budget from 0 to
//! 1000 µs, latency and CPU next to the futex ring of the same depth.
//! Build first: `cargo build --release --workspace && target/release/latency-report`.

use skillfab_bench::Case;
use skillfab_bench::report::{self, Row};
use skillfab_proto::realtime::RealTime;
use std::process::ExitCode;

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let (mut json, mut cycles, mut svg, mut only, mut repeats) =
        (false, 400usize, None, None, 3usize);
    let (mut scale, mut peer, mut spin_curve) = (None, None, false);
    let (mut sizes, mut rates): (Option<Vec<usize>>, Option<Vec<u32>>) = (None, None);
    let mut realtime: Option<RealTime> = None;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--json" => json = true,
            "--cycles" => match args.next().and_then(|n| n.parse().ok()) {
                Some(n) if n > 0 => cycles = n,
                _ => return usage("--cycles needs a positive number"),
            },
            "--repeats" => match args.next().and_then(|n| n.parse().ok()) {
                Some(n) if n > 0 => repeats = n,
                _ => return usage("--repeats needs a positive number"),
            },
            "--svg" => match args.next() {
                Some(f) => svg = Some(f),
                None => return usage("--svg needs a file"),
            },
            "--svg-from" => match args.next() {
                // Redraws the plot of an earlier `--json` report: latency-report --svg-from
                // docs/latency.json --svg docs/latency.svg
                Some(f) => {
                    let rows = std::fs::read_to_string(&f)
                        .ok()
                        .and_then(|t| serde_json::from_str(&t).ok())
                        .and_then(|j| report::rows_from_json(&j));
                    let Some(rows) = rows else {
                        return usage(&format!("{f} is not a latency-report --json output"));
                    };
                    let Some(out) = svg.clone().or_else(|| {
                        args.next()
                            .filter(|a| a == "--svg")
                            .and_then(|_| args.next())
                    }) else {
                        return usage("--svg-from needs --svg FILE before it or after it");
                    };
                    if let Err(e) = std::fs::write(&out, report::to_svg(&rows)) {
                        eprintln!("latency-report: writing {out}: {e}");
                        return ExitCode::FAILURE;
                    }
                    return ExitCode::SUCCESS;
                }
                None => return usage("--svg-from needs a file"),
            },
            "--spin-experiment" => {
                print!("{}", report::spin_experiment(cycles));
                return ExitCode::SUCCESS;
            }
            "--scale" => scale = Some(args.next().and_then(|s| s.parse().ok()).unwrap_or(3.0)),
            "--spin-curve" => spin_curve = true,
            "--sizes" => match args.next().and_then(|s| list(&s)) {
                Some(v) => sizes = Some(v),
                None => return usage("--sizes needs chain lengths, e.g. 6 or 1,6,16"),
            },
            "--rates" => match args.next().and_then(|s| list(&s)) {
                Some(v) => rates = Some(v),
                None => return usage("--rates needs rates in Hz, e.g. 1000 or 100,1000"),
            },
            "--realtime" => match args.next().map(|s| s.parse::<RealTime>()) {
                Some(Ok(rt)) => realtime = Some(rt),
                Some(Err(e)) => return usage(&format!("--realtime: {e}")),
                None => return usage("--realtime needs POLICY:PRIORITY[@CPUS][+mlock]"),
            },
            "--peer" => match args.next().as_deref() {
                Some(p @ ("dora" | "copper")) => peer = Some(p.to_string()),
                _ => return usage("--peer takes 'dora' or 'copper'"),
            },
            "--only" => match args.next() {
                Some(s) => only = Some(s),
                None => return usage("--only needs a substring of case names"),
            },
            "-h" | "--help" => {
                println!(
                    "usage: latency-report [--json] [--cycles N] [--repeats R] [--svg FILE] [--only SUBSTRING] | --scale [SECS] [--sizes N,..] [--rates HZ,..] [--realtime fifo:80[@CPUS][+mlock]] [--json] | --spin-curve [--cycles N] [--repeats R] [--json] | --peer dora|copper [--cycles N] [--repeats R] [--json] | --svg FILE --svg-from REPORT.json"
                );
                return ExitCode::SUCCESS;
            }
            other => return usage(&format!("unknown argument '{other}'")),
        }
    }
    if spin_curve {
        let mut cases: Vec<Case> = [1, 2, 4, 8].into_iter().map(Case::Chain).collect();
        cases.push(Case::ExitLab);
        let points = report::spin_curve(&cases, &[0, 25, 100, 300, 1000], cycles / 2, repeats);
        if json {
            println!("{}", report::spin_curve_json(&points));
        } else {
            print!("{}", report::spin_curve_text(&points));
        }
        return ExitCode::SUCCESS;
    }
    if scale.is_none() && (realtime.is_some() || sizes.is_some() || rates.is_some()) {
        return usage("--sizes, --rates and --realtime go with --scale");
    }
    if let Some(secs) = scale {
        let sizes = sizes.unwrap_or_else(|| vec![1, 2, 4, 6, 8, 16, 32, 64]);
        let rates = rates.unwrap_or_else(|| vec![100, 1000]);
        let points = report::scale(&sizes, &rates, secs, realtime.as_ref());
        if json {
            println!("{}", report::scale_json(&points));
        } else {
            print!("{}", report::scale_text(&points));
        }
        return ExitCode::SUCCESS;
    }
    if let Some(peer) = peer {
        // Paced runs take a period per cycle: half the cycles, as the paced cases below.
        let rows = match peer.as_str() {
            "dora" => skillfab_bench::dora::compare(&[1, 2, 4, 8], cycles / 2, repeats),
            _ => skillfab_bench::copper::compare(
                &skillfab_bench::copper::DEPTHS,
                cycles / 2,
                repeats,
            ),
        };
        return match rows {
            Ok(rows) if json => {
                println!("{}", skillfab_bench::peer::to_json(&peer, &rows));
                ExitCode::SUCCESS
            }
            Ok(rows) if peer == "dora" => {
                print!("{}", skillfab_bench::dora::to_text(&rows));
                ExitCode::SUCCESS
            }
            Ok(rows) => {
                print!("{}", skillfab_bench::copper::to_text(&rows));
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("latency-report --peer {peer}: {e}");
                ExitCode::FAILURE
            }
        };
    }
    let mut rows: Vec<Row> = Vec::new();
    for paced in [false, true] {
        for case in Case::all() {
            let name = if paced {
                format!("{}@100Hz", case.name())
            } else {
                case.name()
            };
            if only.as_ref().is_some_and(|o| !name.contains(o.as_str())) {
                continue;
            }
            // Paced runs take a period per cycle: fewer of them.
            let n = if paced { cycles / 2 } else { cycles }.max(10);
            let r = report::row(case, paced, n, repeats);
            eprintln!(
                "{name}: skillfab p50 {:.0} µs, iceoryx2 ring p50 {:.0} µs",
                r.skillfab.p50, r.floors[0].1.p50
            );
            rows.push(r);
        }
    }
    let idle = report::idle(5.0, repeats);
    let work: Vec<_> = [Case::ExitLab, Case::Chain(6)]
        .into_iter()
        .map(|c| {
            (
                format!("{}@100Hz", c.name()),
                report::manager_work(c, cycles.max(100)),
            )
        })
        .collect();
    if json {
        println!("{}", report::to_json(&rows, &idle, &work));
    } else {
        print!("{}", report::to_text(&rows, &idle, &work));
    }
    if let Some(f) = svg
        && let Err(e) = std::fs::write(&f, report::to_svg(&rows))
    {
        eprintln!("latency-report: writing {f}: {e}");
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}

fn usage(why: &str) -> ExitCode {
    eprintln!(
        "latency-report: {why}\nusage: latency-report [--json] [--cycles N] [--repeats R] [--svg FILE] [--only SUBSTRING] | --scale [SECS] [--sizes N,..] [--rates HZ,..] [--realtime fifo:80[@CPUS][+mlock]] [--json] | --svg FILE --svg-from REPORT.json"
    );
    ExitCode::from(2)
}

/// A comma-separated list of positive numbers.
fn list<T: std::str::FromStr + PartialOrd + Default>(s: &str) -> Option<Vec<T>> {
    s.split(',')
        .map(|x| x.trim().parse::<T>().ok().filter(|v| *v > T::default()))
        .collect()
}
