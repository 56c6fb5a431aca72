//! A real lossy link between two hosts: the sensor side (publisher + `bridge --side sensor`)
//! and the estimator side (`bridge --side estimator` + runner) in two network namespaces
//! joined by a veth pair, zenoh over UDP, and the kernel dropping 10 % of the datagrams from
//! the sensor host (docs/bridge.md, "A lossy link").
//!
//! * The estimators see those losses as losses: every instant is accounted for, the slots
//!   lost are counted as lost on the network by the bridge and the runner alike, and their
//!   number is Binomial(N, 0.1) within 4.5 standard deviations (the kernel's drop decisions
//!   are not seeded: 4.5 σ fails by chance about once in 150 000 runs). What the bridge
//!   counts matches what the kernel counted as dropped.
//! * Nothing else is degraded: the run's slot log replays to the live estimates bit for bit,
//!   so the estimators' error is what the lost instants' information explains, and nothing
//!   more; the same log with the losses mistaken for channel dropouts (which carry
//!   information in the occlusion model) gives a larger error.
//!
//! The loss is `tc netem loss 10%` where the kernel has netem, else an nftables rule
//! `numgen random mod 1000 < 100 drop` on the same veth (this VM's kernel has no netem).
//! Without root, `ip netns`, or either way of dropping, the test is skipped with one line.

#[path = "bridge_common.rs"]
mod bridge_common;
#[path = "pipeline_common.rs"]
mod common;
#[path = "netns_common.rs"]
mod netns;
#[path = "skip_log.rs"]
mod skip_log;

use bridge_common::assert_ok;

use common::{report, scratch, Proc};
use netns::{Netns, ADDR_A};
use std::path::Path;

const LOSS: f64 = 0.1;
const STEPS: u32 = 2000;
const PORT: u16 = 7449;

/// Two network namespaces ([`Netns`]), the link from A to B losing [`LOSS`] of its
/// datagrams.
struct Link {
    ns: Netns,
    /// How the kernel drops: "netem" or "nftables".
    how: &'static str,
}

impl std::ops::Deref for Link {
    type Target = Netns;
    fn deref(&self) -> &Netns {
        &self.ns
    }
}

impl Link {
    fn new() -> Result<Self, String> {
        let ns = Netns::pair('l')?;
        let pct = format!("{}%", LOSS * 100.0);
        let (va, vb) = (&ns.va, &ns.vb);
        let how = match ns.exec(
            &ns.a,
            &[
                "tc", "qdisc", "add", "dev", va, "root", "netem", "loss", &pct,
            ],
        ) {
            Ok(_) => "netem",
            Err(netem) => {
                let per_mille = format!("{}", (LOSS * 1000.0).round() as u32);
                // On B's way in: a datagram dropped on A's way out would fail A's sendto()
                // with EPERM, which zenoh takes as a broken link; netem's drop is silent.
                let rule = format!(
                    "iifname \"{vb}\" udp sport {PORT} numgen random mod 1000 < {per_mille} \
                     counter drop"
                );
                let chain = "{ type filter hook input priority 0; }";
                ns.exec(&ns.b, &["nft", "add", "table", "inet", "estp"])
                    .and_then(|_| {
                        ns.exec(
                            &ns.b,
                            &["nft", "add", "chain", "inet", "estp", "inp", chain],
                        )
                    })
                    .and_then(|_| {
                        ns.exec(&ns.b, &["nft", "add", "rule", "inet", "estp", "inp", &rule])
                    })
                    .map_err(|nft| format!("no way to drop: {netem}; {nft}"))?;
                "nftables"
            }
        };
        Ok(Self { ns, how })
    }

    /// Datagrams the kernel dropped on the A → B link so far.
    fn dropped(&self) -> u64 {
        let out = if self.how == "netem" {
            self.exec(&self.a, &["tc", "-s", "qdisc", "show"]).unwrap()
        } else {
            self.exec(&self.b, &["nft", "list", "table", "inet", "estp"])
                .unwrap()
        };
        let word = if self.how == "netem" {
            "dropped"
        } else {
            "packets"
        };
        let w: Vec<&str> = out
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .collect();
        let i = w
            .iter()
            .position(|s| *s == word)
            .unwrap_or_else(|| panic!("no {word} in {out}"));
        // netem prints "dropped N", nftables "packets N".
        w[i + 1].parse().unwrap()
    }
}

/// Per estimator column prefix: the mean over instants of ‖x̂ − x‖² against the truth
/// columns of `truth_csv` (the live run's `--estimates-csv`), for the estimates in `csv`
/// (columns `<name>_<j>`, rows in the same instants).
fn mse(truth_csv: &Path, csv: &Path, names: &[&str]) -> Vec<f64> {
    let (th, tr) = common::csv(truth_csv);
    let (h, rows) = common::csv(csv);
    assert_eq!(tr.len(), rows.len());
    let truth: Vec<usize> = (0..th.len())
        .filter(|&i| th[i].starts_with("truth_"))
        .collect();
    names
        .iter()
        .map(|n| {
            let cols: Vec<usize> = (0..truth.len())
                .map(|j| {
                    h.iter()
                        .position(|c| *c == format!("{n}_{j}"))
                        .unwrap_or_else(|| panic!("no {n}_{j} in {h:?}"))
                })
                .collect();
            // Instants whose truth the network lost are not scored (as in the runner).
            let scored: Vec<(&Vec<f64>, &Vec<f64>)> = tr
                .iter()
                .zip(&rows)
                .filter(|(t, _)| truth.iter().all(|&ti| t[ti].is_finite()))
                .collect();
            let sum: f64 = scored
                .iter()
                .map(|(t, r)| {
                    truth
                        .iter()
                        .zip(&cols)
                        .map(|(&ti, &ci)| (t[ti] - r[ci]).powi(2))
                        .sum::<f64>()
                })
                .sum();
            sum / scored.len() as f64
        })
        .collect()
}

/// The slot log with every network-lost row (flag bit 30) rewritten as a channel dropout:
/// what a receiver that cannot tell the two apart would feed its estimators.
fn as_dropouts(log: &Path, out: &Path) -> usize {
    let s = std::fs::read_to_string(log).unwrap();
    let mut lines = s.lines();
    let head = lines.next().unwrap();
    let flags = head.split(',').position(|c| c == "flags").unwrap();
    let mut n = 0;
    let mut w = String::from(head);
    w.push('\n');
    for l in lines {
        let mut f: Vec<String> = l.split(',').map(str::to_owned).collect();
        let v: u64 = f[flags].parse().unwrap();
        if v & (1 << 30) != 0 {
            f[flags] = (v & !(1 << 30)).to_string();
            n += 1;
        }
        w.push_str(&f.join(","));
        w.push('\n');
    }
    std::fs::write(out, w).unwrap();
    n
}

#[test]
fn a_lossy_link_is_seen_as_losses_and_costs_only_their_information() {
    let link = match Link::new() {
        Ok(l) => l,
        Err(why) => {
            skip_log::skipped(
                &skip_log::current_test("lossy_link"),
                &format!("no lossy link between network namespaces here ({why})"),
            );
            return;
        }
    };
    let dir = scratch("lossy-link");
    let (a, b) = (common::prefix("lossy-a"), common::prefix("lossy-b"));
    let key = format!("estpipe-test/{}", common::prefix("key"));
    let endpoint = format!("udp/{ADDR_A}:{PORT}");
    let bridge = |nsn: &str, side, role, prefix| {
        let b = netns::BridgeArgs {
            side,
            role,
            prefix,
            key: &key,
            endpoint: &endpoint,
        };
        link.bridge(nsn, &dir, &b, &["--once"])
    };
    let (csv, json, log) = (
        dir.join("run.csv"),
        dir.join("run.json"),
        dir.join("slots.csv"),
    );
    let steps = STEPS.to_string();
    // The listening side first: a UDP connect to a port nobody listens on yet gets an ICMP
    // "port unreachable", which zenoh's UDP link takes as a failed link.
    let mut sen = bridge(&link.a, "sensor", "--listen", &a);
    sen.wait_for_stderr("waiting for the estimator side", 30);
    let mut est = bridge(&link.b, "estimator", "--connect", &b);
    let mut run = link.start(
        &link.b,
        &dir,
        "run",
        &[
            "run",
            "--scenario",
            "occlusion",
            "--prefix",
            &b,
            "--steps",
            &steps,
            "--wait",
            "block",
            "--buffer",
            "4096",
            "--estimates-csv",
            csv.to_str().unwrap(),
            "--slots-csv",
            log.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
            "--quiet",
        ],
    );
    let dropped_before = link.dropped();
    let mut publ = link.start(
        &link.a,
        &dir,
        "pub",
        &[
            "channel-sim",
            "--scenario",
            "occlusion",
            "--prefix",
            &a,
            "--rate",
            "2000",
            "--steps",
            &steps,
            "--quiet",
        ],
    );
    assert_ok(&mut publ, 120);
    assert_ok(&mut run, 120);
    assert_ok(&mut est, 60);
    assert_ok(&mut sen, 60);
    let dropped = link.dropped() - dropped_before;

    let e = report(&dir.join("bridge-estimator.json"));
    let s = report(&dir.join("bridge-sensor.json"));
    let r = report(&json);
    let n = u64::from(STEPS);
    let get = |v: &serde_json::Value, k: &str| v[k].as_u64().unwrap();
    let lost = get(&e, "lost_on_network");
    // Every instant accounted for: arrived or lost on the network, never anything else.
    assert_eq!(get(&s, "slots"), n, "the sensor side sent every slot");
    assert_eq!(get(&e, "slots") + lost, n, "{e}");
    assert_eq!(e["refused"], serde_json::json!({}), "{e}");
    assert_eq!(r["counts"]["lost_on_network"].as_u64().unwrap(), lost);
    assert_eq!(r["counts"]["received"].as_u64().unwrap(), n - lost);
    // Binomial(N, p): mean Np, sd sqrt(Np(1 − p)).
    let (mean, sd) = (n as f64 * LOSS, (n as f64 * LOSS * (1.0 - LOSS)).sqrt());
    assert!(
        (lost as f64 - mean).abs() <= 4.5 * sd,
        "lost {lost} of {n}: outside {mean} ± 4.5 × {sd:.1}"
    );
    // What the kernel dropped is what the bridge misses: slots, truth samples, marker repeats,
    // and the few zenoh control messages (keep-alives) on the same link.
    let missed = lost
        + (get(&s, "truth") - get(&e, "truth"))
        + (get(&s, "marker_puts") - get(&e, "markers") - get(&e, "markers_repeated"));
    eprintln!(
        "{} dropped {dropped} datagrams; the bridge missed {missed} messages ({lost} slots)",
        link.how
    );
    assert!(
        missed <= dropped && dropped <= missed + 20,
        "kernel dropped {dropped}, bridge missed {missed}"
    );

    // The log replays to the live estimates bit for bit: the network took the lost instants'
    // information and nothing else.
    let names = ["ikf", "cce", "adf", "kf-io"];
    let replayed = dir.join("replayed.csv");
    let mut rp = Proc::start(
        &dir,
        "replay",
        &[
            "replay",
            "--input",
            log.to_str().unwrap(),
            "--scenario",
            "occlusion",
            "--output",
            replayed.to_str().unwrap(),
        ],
    );
    assert_ok(&mut rp, 120);
    // Replay counts the network's losses apart from the channel's dropouts.
    let said = std::fs::read_to_string(&rp.stdout).unwrap();
    assert!(
        said.contains(&format!(", {lost} lost on the network")),
        "replay said: {said}"
    );
    let live = mse(&csv, &csv, &names);
    let again = mse(&csv, &replayed, &names);
    for (i, name) in names.iter().enumerate() {
        assert_eq!(live[i].to_bits(), again[i].to_bits(), "{name}");
    }
    // Mistaken for dropouts (the occlusion model reads a dropout as "the target is occluded"),
    // the same losses cost more than their information.
    let wrong_log = dir.join("as-dropouts.csv");
    assert_eq!(as_dropouts(&log, &wrong_log) as u64, lost);
    let wrong_out = dir.join("as-dropouts-est.csv");
    let mut rp = Proc::start(
        &dir,
        "replay-wrong",
        &[
            "replay",
            "--input",
            wrong_log.to_str().unwrap(),
            "--scenario",
            "occlusion",
            "--output",
            wrong_out.to_str().unwrap(),
        ],
    );
    assert_ok(&mut rp, 120);
    let wrong = mse(&csv, &wrong_out, &names);
    eprintln!("MSE over the lossy link {live:?}; losses taken for dropouts {wrong:?}");
    for (i, name) in names.iter().enumerate().skip(1) {
        assert!(wrong[i] > live[i], "{name}: {} vs {}", wrong[i], live[i]);
    }
    let _ = std::fs::remove_dir_all(&dir);
    drop(link);
}
