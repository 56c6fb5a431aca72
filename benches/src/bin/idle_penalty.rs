//! What idling costs on this machine: the same small piece of work timed **back to back** and
//! **paced** (once per period, spinning on the clock in between, as `ipc-runner --wait spin`
//! waits for its next slot).
//!
//! The pipeline's end-to-end tail is the IPC hop plus the runner's own work on one instant,
//! and that work runs after up to a period of idling. If the caches and TLB it needs have gone
//! cold meanwhile (on a VM, whatever else runs on the host's core), its tail grows although
//! the code is the same. This measures that floor independently of the pipeline:
//!
//! - `touch 16 KiB`: read-modify-write of one `u64` per cache line of a 16 KiB buffer (a
//!   fixed reference working set, half an L1d);
//! - `iceoryx2 loan+send`: `loan_uninit` + `write_payload` + `send` of one
//!   `estpipe_wire::Estimate` on a service of its own with no subscriber (the runner's
//!   publish as it was before it loaned ahead);
//! - `iceoryx2 send, loaned ahead`: `write_payload` + `send` of a sample loaned right after
//!   the previous send, off the clock (the runner's publish now).
//!
//! ```text
//! idle_penalty [--samples N (30000)] [--rate HZ (10000)] [--json]
//! ```
//!
//! The service name contains the pid; the service goes with the process (iceoryx2 removes it
//! when its last port is dropped, and `try_cleanup_dead_nodes` of any later node after a
//! crash).

use anyhow::{anyhow, bail, Context, Result};
use estpipe_wire::{self as wire, monotonic_ns, Estimate};
use hdrhistogram::Histogram;
use iceoryx2::prelude::*;
use ipc_runner::latency::Percentiles;
use std::hint::black_box;

/// A sample loaned from the probe's publisher.
type PreLoaned = iceoryx2::sample_mut_uninit::SampleMutUninit<
    ipc::Service,
    core::mem::MaybeUninit<Estimate>,
    (),
>;

/// The works, in output order.
const WORKS: [&str; 3] = [
    "touch 16 KiB",
    "iceoryx2 loan+send",
    "iceoryx2 send, loaned ahead",
];

struct Args {
    samples: u32,
    rate: f64,
    json: bool,
}

fn parse() -> Result<Args> {
    let mut a = Args {
        samples: 30_000,
        rate: 10_000.0,
        json: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(x) = it.next() {
        let mut val = |name: &str| it.next().with_context(|| format!("{name} needs a value"));
        match x.as_str() {
            "--samples" => {
                let v = val("--samples")?;
                a.samples =
                    v.parse().ok().filter(|&n| n > 0).with_context(|| {
                        format!("--samples must be a positive integer, got {v:?}")
                    })?;
            }
            "--rate" => {
                let v = val("--rate")?;
                a.rate = v
                    .parse()
                    .ok()
                    .filter(|r: &f64| r.is_finite() && *r > 0.0 && *r <= 1e6)
                    .with_context(|| format!("--rate must be in (0, 1e6] Hz, got {v:?}"))?;
            }
            "--json" => a.json = true,
            "-h" | "--help" => {
                println!("idle_penalty [--samples N (30000)] [--rate HZ (10000)] [--json]");
                std::process::exit(0);
            }
            _ => bail!("unknown argument {x:?} (see --help)"),
        }
    }
    Ok(a)
}

/// Times `work` `n` times: back to back when `period_ns` is 0, else once per period with a
/// spin on the clock in between. `work` returns its own (start, end) so that set-up it does
/// off the clock (a loan ahead) is not timed.
fn time(
    n: u32,
    period_ns: u64,
    work: &mut impl FnMut() -> Result<(u64, u64)>,
) -> Result<Percentiles> {
    let mut h = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3)?;
    let mut due = monotonic_ns() + period_ns;
    for _ in 0..n {
        if period_ns > 0 {
            while monotonic_ns() < due {
                core::hint::spin_loop();
            }
            due += period_ns;
        }
        let (t0, t1) = work()?;
        h.record(t1.saturating_sub(t0).max(1))?;
    }
    Ok(Percentiles::of(&h))
}

fn run(a: &Args) -> Result<Vec<(&'static str, Percentiles, Percentiles)>> {
    let period = (1e9 / a.rate) as u64;
    let warm = a.samples.min(1000);
    let mut buf = vec![1u64; 16 * 1024 / 8];
    let mut touch = || {
        let t0 = monotonic_ns();
        let mut s = 0u64;
        for v in buf.iter_mut().step_by(8) {
            s = s.wrapping_add(*v);
            *v = s;
        }
        black_box(s);
        Ok((t0, monotonic_ns()))
    };
    let node = NodeBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("iceoryx2 node: {e:?}"))?;
    let _ = node.try_cleanup_dead_nodes();
    let service = wire::estimate_service(&node, &format!("idle-penalty-{}", std::process::id()))?;
    let publisher = service
        .publisher_builder()
        .max_loaned_samples(2)
        .create()
        .map_err(|e| anyhow!("publisher: {e:?}"))?;
    let msg = Estimate::none_yet(0, Estimate::encode_name("probe"));
    let loan = || publisher.loan_uninit().map_err(|e| anyhow!("loan: {e:?}"));
    let send = |s: PreLoaned| {
        s.write_payload(msg)
            .send()
            .map_err(|e| anyhow!("send: {e:?}"))
    };
    let mut loan_send = || {
        let t0 = monotonic_ns();
        send(loan()?)?;
        Ok((t0, monotonic_ns()))
    };
    let mut out = Vec::new();
    time(warm, 0, &mut touch)?;
    out.push((
        WORKS[0],
        time(a.samples, 0, &mut touch)?,
        time(a.samples, period, &mut touch)?,
    ));
    time(warm, 0, &mut loan_send)?;
    out.push((
        WORKS[1],
        time(a.samples, 0, &mut loan_send)?,
        time(a.samples, period, &mut loan_send)?,
    ));
    let mut held = None;
    let mut send_ahead = || {
        let t0 = monotonic_ns();
        send(match held.take() {
            Some(s) => s,
            None => loan()?,
        })?;
        let t1 = monotonic_ns();
        held = Some(loan()?);
        Ok((t0, t1))
    };
    time(warm, 0, &mut send_ahead)?;
    out.push((
        WORKS[2],
        time(a.samples, 0, &mut send_ahead)?,
        time(a.samples, period, &mut send_ahead)?,
    ));
    Ok(out)
}

fn main() {
    let a = match parse() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("idle_penalty: {e:#}");
            std::process::exit(2);
        }
    };
    let rows = match run(&a) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("idle_penalty: {e:#}");
            std::process::exit(1);
        }
    };
    if a.json {
        let v: Vec<serde_json::Value> = rows
            .iter()
            .map(|(w, b2b, paced)| {
                serde_json::json!({
                    "work": w, "samples": a.samples, "rate_hz": a.rate,
                    "back_to_back": b2b, "paced": paced,
                })
            })
            .collect();
        println!("{}", serde_json::Value::Array(v));
        return;
    }
    println!(
        "{} samples each; paced = one every {:.1} µs, spinning on the clock in between",
        a.samples,
        1e6 / a.rate
    );
    println!(
        "{:<28} {:>22} {:>22} {:>10}",
        "work", "back to back p50/p99", "paced p50/p99", "p99 ratio"
    );
    for (w, b, p) in &rows {
        println!(
            "{w:<28} {:>10.3} / {:<9.3} {:>10.3} / {:<9.3} {:>9.2}×",
            b.p50_us,
            b.p99_us,
            p.p50_us,
            p.p99_us,
            p.p99_us / b.p99_us
        );
    }
}
