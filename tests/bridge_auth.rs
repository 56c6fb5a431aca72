//! Issue #39, item 9: the zenoh link authenticated, as docs/security.md ("The zenoh link")
//! says to deploy it — mutual TLS, user/password and access control in the two sides'
//! `--zenoh-config` files, with certificates this test makes itself (rcgen) on loopback.
//!
//! * The authenticated estimator side gets through: the run's estimates equal a direct run's
//!   bit for bit, every slot forwarded, nothing refused or lost.
//! * A peer without credentials, one with a certificate of another authority, and one with a
//!   good certificate but a wrong password cannot join (zenoh refuses the handshake): each
//!   reports no session, nothing published, nothing received.
//! * A peer with valid credentials whose identity (`monitor`) may only subscribe
//!   `<key>/estimates` joins and receives estimates, but its 200 messages on `<key>/slots`
//!   are denied by the sensor side's access control: none reaches the estimator side, which
//!   would have counted each one as refused.
//!
//! The checks a build makes on such files (exit 2, one line) are in
//! `tests/hostile_consumers.rs` and the bridge's own unit tests.

#[path = "bridge_common.rs"]
mod bridge_common;
#[path = "pipeline_common.rs"]
mod common;

use bridge_common::{assert_ok, estimates, free_port, publisher, runner, Chain};
use common::{report, Proc};
use rcgen::{
    BasicConstraints, CertificateParams, CertifiedIssuer, DnType, ExtendedKeyUsagePurpose, IsCa,
    KeyPair, KeyUsagePurpose, SanType,
};
use std::path::{Path, PathBuf};

const STEPS: u32 = 600;
/// 3 s of stream: the peers below try while it flows.
const RATE: u32 = 200;
/// Messages the `monitor` peer publishes on `<key>/slots`.
const FORBIDDEN_PUTS: u64 = 200;

/// A certificate authority of this test.
fn authority(name: &str) -> CertifiedIssuer<'static, KeyPair> {
    let mut p = CertificateParams::new(Vec::<String>::new()).unwrap();
    p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    p.distinguished_name.push(DnType::CommonName, name);
    p.key_usages = vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::DigitalSignature,
    ];
    CertifiedIssuer::self_signed(p, KeyPair::generate().unwrap()).unwrap()
}

/// A certificate with common name `cn` (the access control's subject) for loopback, signed
/// by `ca`, written as `dir/<file>.pem` and `dir/<file>.key`; their paths.
fn certificate(
    dir: &Path,
    file: &str,
    cn: &str,
    ca: &CertifiedIssuer<'static, KeyPair>,
) -> (PathBuf, PathBuf) {
    let key = KeyPair::generate().unwrap();
    let mut p = CertificateParams::new(vec!["localhost".to_string()]).unwrap();
    p.subject_alt_names
        .push(SanType::IpAddress(std::net::Ipv4Addr::LOCALHOST.into()));
    p.distinguished_name.push(DnType::CommonName, cn);
    p.extended_key_usages = vec![
        ExtendedKeyUsagePurpose::ServerAuth,
        ExtendedKeyUsagePurpose::ClientAuth,
    ];
    let cert = p.signed_by(&key, ca).unwrap();
    let (c, k) = (
        dir.join(format!("{file}.pem")),
        dir.join(format!("{file}.key")),
    );
    std::fs::write(&c, cert.pem()).unwrap();
    std::fs::write(&k, key.serialize_pem()).unwrap();
    (c, k)
}

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

/// The TLS section of a side that connects with `cert`, or of a listener with `listen`.
fn tls(
    ca: &Path,
    listen: Option<&(PathBuf, PathBuf)>,
    cert: Option<&(PathBuf, PathBuf)>,
) -> serde_json::Value {
    let mut t = serde_json::json!({ "root_ca_certificate": s(ca), "enable_mtls": true });
    if let Some((c, k)) = listen {
        t["listen_certificate"] = s(c).into();
        t["listen_private_key"] = s(k).into();
    }
    if let Some((c, k)) = cert {
        t["connect_certificate"] = s(c).into();
        t["connect_private_key"] = s(k).into();
    }
    t
}

/// The sensor side's access control: only `estimator` (certificate and user name) may
/// subscribe `<key>/slots` and publish `<key>/estimates` (and `<key>/acks`, the END markers'
/// acknowledgements); `monitor` may only subscribe
/// `<key>/estimates`; everything else is denied. `enabled: false` is the control.
fn access_control(key: &str, enabled: bool) -> serde_json::Value {
    let rule = |id: &str, flow: &str, messages: &[&str], keys: &[&str]| {
        serde_json::json!({
            "id": id,
            "flows": [flow],
            "messages": messages,
            "key_exprs": keys.iter().map(|k| format!("{key}/{k}")).collect::<Vec<_>>(),
            "permission": "allow",
        })
    };
    serde_json::json!({
        "enabled": enabled,
        "default_permission": "deny",
        "rules": [
            rule("estimator-subscribes-slots", "ingress", &["declare_subscriber"], &["slots"]),
            rule("estimator-publishes-estimates", "ingress", &["put"], &["estimates", "acks"]),
            rule("estimator-watches-sensor", "ingress",
                 &["declare_liveliness_subscriber", "liveliness_query"], &["alive/sensor"]),
            rule("to-estimator", "egress", &["put"], &["slots"]),
            rule("to-estimator-interest", "egress", &["declare_subscriber"], &["estimates", "acks"]),
            rule("to-estimator-alive", "egress", &["liveliness_token", "reply"], &["alive/sensor"]),
            rule("monitor-subscribes-estimates", "ingress", &["declare_subscriber"], &["estimates"]),
            rule("to-monitor", "egress", &["put"], &["estimates"]),
        ],
        "subjects": [
            { "id": "estimator", "cert_common_names": ["estimator"], "usernames": ["estimator"] },
            { "id": "monitor", "cert_common_names": ["monitor"], "usernames": ["monitor"] },
        ],
        "policies": [
            { "subjects": ["estimator"], "rules": [
                "estimator-subscribes-slots", "estimator-publishes-estimates",
                "estimator-watches-sensor", "to-estimator", "to-estimator-interest",
                "to-estimator-alive"] },
            { "subjects": ["monitor"], "rules": ["monitor-subscribes-estimates", "to-monitor"] },
        ],
    })
}

/// A zenoh configuration file `dir/<name>.json5`.
fn config(dir: &Path, name: &str, v: serde_json::Value) -> String {
    let p = dir.join(format!("{name}.json5"));
    std::fs::write(&p, serde_json::to_string_pretty(&v).unwrap()).unwrap();
    s(&p)
}

/// A peer's configuration: connects to `endpoint`, listens nowhere, with `tls` and the
/// user/password `usrpwd` if given.
fn peer_config(
    dir: &Path,
    name: &str,
    endpoint: &str,
    tls: serde_json::Value,
    usrpwd: Option<(&str, &str)>,
) -> String {
    let mut v = serde_json::json!({
        "mode": "client",
        "scouting": { "multicast": { "enabled": false } },
        "listen": { "endpoints": [] },
        "connect": { "endpoints": [endpoint] },
        "transport": { "link": { "tls": tls } },
    });
    if let Some((u, p)) = usrpwd {
        v["transport"]["auth"] = serde_json::json!({ "usrpwd": { "user": u, "password": p } });
    }
    config(dir, name, v)
}

/// `zenoh-peer` with `config` on `key`: publishes `puts` messages on `<key>/slots` once
/// joined and listens on `<key>/estimates` for `listen_ms`.
fn peer(dir: &Path, name: &str, config: &str, key: &str, puts: u64, listen_ms: u64) -> Proc {
    let (puts, listen_ms) = (puts.to_string(), listen_ms.to_string());
    Proc::start_program(
        dir,
        name,
        Path::new(env!("CARGO_BIN_EXE_zenoh-peer")),
        &[
            "--config",
            config,
            "--key",
            key,
            "--join-ms",
            "3000",
            "--publish",
            &puts,
            "--listen-ms",
            &listen_ms,
        ],
    )
}

/// What a peer got (its JSON line on stdout), after it exited 0.
fn peer_result(p: &mut Proc) -> serde_json::Value {
    assert_ok(p, 30);
    serde_json::from_str(p.out().trim()).unwrap_or_else(|e| panic!("{}: {e}: {}", p.name, p.out()))
}

/// What a secured run gave: the peers' results by name, the estimator side's and the
/// runner's reports, and whether the estimates equal the direct run's.
struct Secured {
    dir: PathBuf,
    peers: Vec<(String, serde_json::Value)>,
    est: serde_json::Value,
    run: serde_json::Value,
    same_estimates: bool,
}

/// A direct run, then the same stream over the authenticated bridge (the sensor side a
/// zenoh router with mutual TLS, user/password and, if `acl`, the access control) while
/// `intruders` (those without valid credentials) and the monitor try to join.
fn secured_run(test: &str, acl: bool, intruders: bool) -> Secured {
    let mut c = Chain::new(test);
    c.endpoint = format!("tls/127.0.0.1:{}", free_port());
    let dir = c.dir.clone();

    // The direct run: the estimates an undisturbed stream gives.
    let direct = common::prefix(&format!("{test}-direct"));
    let mut run = runner(&dir, "direct", &direct, STEPS, &[]);
    std::thread::sleep(std::time::Duration::from_millis(200));
    let mut publ = publisher(&dir, "pub-direct", &direct, STEPS, 2000);
    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);

    // Certificates: the deployment's authority, and another one nobody trusts.
    let ca = authority("estpipe test CA");
    let rogue = authority("rogue CA");
    let ca_pem = dir.join("ca.pem");
    std::fs::write(&ca_pem, ca.pem()).unwrap();
    let sensor = certificate(&dir, "sensor", "sensor", &ca);
    let estimator = certificate(&dir, "estimator", "estimator", &ca);
    let monitor = certificate(&dir, "monitor", "monitor", &ca);
    let forged = certificate(&dir, "forged", "estimator", &rogue);
    let users = dir.join("users.txt");
    std::fs::write(&users, "estimator:est-secret\nmonitor:mon-secret\n").unwrap();

    // The sensor side routes between the peers that join it (a zenoh peer would not
    // forward between two others), so its access control decides for all of them.
    let sensor_cfg = config(
        &dir,
        "sensor",
        serde_json::json!({
            "mode": "router",
            "scouting": { "multicast": { "enabled": false } },
            "transport": {
                "link": { "tls": tls(&ca_pem, Some(&sensor), None) },
                "auth": { "usrpwd": { "dictionary_file": s(&users) } },
            },
            "access_control": access_control(&c.key, acl),
        }),
    );
    let estimator_cfg = config(
        &dir,
        "estimator",
        serde_json::json!({
            "mode": "peer",
            "scouting": { "multicast": { "enabled": false } },
            "listen": { "endpoints": [] },
            "transport": {
                "link": { "tls": tls(&ca_pem, None, Some(&estimator)) },
                "auth": { "usrpwd": { "user": "estimator", "password": "est-secret" } },
            },
        }),
    );

    let mut est = c.estimator("estimator", &["--zenoh-config", &estimator_cfg]);
    let mut run = c.runner("bridged", STEPS, &[]);
    let mut sen = c.sensor("sensor", &["--zenoh-config", &sensor_cfg]);
    sen.wait_for_stderr("forwarding", 30);

    let ep = c.endpoint.clone();
    let mut peers = Vec::new();
    if intruders {
        let anonymous = peer_config(&dir, "anonymous", &ep, tls(&ca_pem, None, None), None);
        let wrong_ca = peer_config(
            &dir,
            "wrong-ca",
            &ep,
            tls(&ca_pem, None, Some(&forged)),
            Some(("estimator", "est-secret")),
        );
        let wrong_pw = peer_config(
            &dir,
            "wrong-password",
            &ep,
            tls(&ca_pem, None, Some(&monitor)),
            Some(("monitor", "guessed")),
        );
        for (n, cfg) in [
            ("anonymous", &anonymous),
            ("wrong-ca", &wrong_ca),
            ("wrong-password", &wrong_pw),
        ] {
            peers.push(peer(&dir, n, cfg, &c.key, FORBIDDEN_PUTS, 500));
        }
    }
    let monitor_cfg = peer_config(
        &dir,
        "monitor",
        &ep,
        tls(&ca_pem, None, Some(&monitor)),
        Some(("monitor", "mon-secret")),
    );
    let mon = peer(&dir, "monitor", &monitor_cfg, &c.key, FORBIDDEN_PUTS, 4000);
    mon.wait_for_stderr("zenoh-peer: joined", 30);
    peers.push(mon);
    let mut publ = c.publisher("pub", STEPS, RATE);

    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);
    assert_ok(&mut est, 30);
    assert_ok(&mut sen, 30);
    let peers = peers
        .iter_mut()
        .map(|p| (p.name.clone(), peer_result(p)))
        .collect();
    let same_estimates = {
        let d = estimates(&dir.join("direct.csv"));
        assert_eq!(d.len(), STEPS as usize);
        d == estimates(&dir.join("bridged.csv"))
    };
    Secured {
        est: report(&dir.join("bridge-estimator.json")),
        run: report(&dir.join("bridged.json")),
        dir,
        peers,
        same_estimates,
    }
}

/// The monitor's result: it joined, published [`FORBIDDEN_PUTS`], received estimates (at
/// most what the estimator side sent), and was told of a subscriber of `<key>/slots` only
/// without the access control; how many estimates.
fn monitor_joined(r: &Secured, acl: bool) -> u64 {
    let (_, m) = r.peers.iter().find(|(n, _)| n == "monitor").unwrap();
    assert_eq!(m["connected"], true, "{m}");
    assert_eq!(m["put"], FORBIDDEN_PUTS, "{m}");
    let seen = m["received"].as_u64().unwrap();
    let sent = r.est["estimates"].as_u64().unwrap();
    assert!(
        seen > 0 && seen <= sent,
        "monitor received {seen} of {sent}: {m}"
    );
    // Whether a subscriber of `<key>/slots` was announced to it.
    assert_eq!(m["matched"], !acl, "{m}");
    seen
}

#[test]
fn only_the_authenticated_estimator_side_gets_through_and_the_estimates_are_unaffected() {
    let r = secured_run("auth", true, true);
    // Refused: no session, nothing in, nothing out — counted here, one by one.
    let mut refused = 0;
    for (name, p) in r.peers.iter().filter(|(n, _)| n != "monitor") {
        assert_eq!(p["connected"], false, "{name}: {p}");
        assert!(p["open_error"].is_string(), "{name}: {p}");
        assert_eq!(p["received"].as_u64().unwrap_or(0), 0, "{name}: {p}");
        assert_eq!(p["put"].as_u64().unwrap_or(0), 0, "{name}: {p}");
        refused += 1;
    }
    assert_eq!(refused, 3);
    // The monitor is in and reads the estimates; its slots are denied.
    // The estimator side's subscription of `<key>/slots` is not even announced to it.
    let seen = monitor_joined(&r, true);
    eprintln!(
        "3 peers refused; the monitor received {seen} estimates, its {FORBIDDEN_PUTS} slots denied"
    );
    // The estimator side: every slot of the stream, and not one message of anybody else (a
    // monitor's message would have been refused as `version` and counted: see the control).
    let (e, run) = (&r.est, &r.run);
    assert_eq!(e["slots"], u64::from(STEPS), "{e}");
    assert_eq!(e["refused"], serde_json::json!({}), "{e}");
    assert_eq!(e["lost_on_network"], 0, "{e}");
    assert_eq!(run["counts"]["lost_on_network"], 0, "{run}");
    assert_eq!(run["counts"]["received"], u64::from(STEPS), "{run}");
    assert_eq!(run["sessions"], 1, "{run}");
    assert!(
        r.same_estimates,
        "the authenticated run's estimates differ from the direct run's"
    );
    let _ = std::fs::remove_dir_all(&r.dir);
}

/// The control: the same monitor without the access control reaches the estimator side,
/// which counts every one of its messages as refused — so the count of 0 above is the
/// access control's doing, not the routing's.
#[test]
fn without_the_access_control_the_monitors_slots_reach_the_estimator_side() {
    let r = secured_run("auth-noacl", false, false);
    monitor_joined(&r, false);
    // zenoh may drop some of a burst of puts on its way (congestion control `Drop`, as on
    // CI's machine: 195 of 200 arrived, and one real slot was lost beside them): what
    // matters is that they arrive at all without the access control.
    let refused = r.est["refused"]["version"].as_u64().unwrap_or(0);
    assert!(refused > 0 && refused <= FORBIDDEN_PUTS, "{}", r.est);
    let lost = r.est["lost_on_network"].as_u64().unwrap();
    assert_eq!(
        r.est["slots"].as_u64().unwrap() + lost,
        u64::from(STEPS),
        "{}",
        r.est
    );
    // The contract's checks kept them out of shared memory: with every real slot through,
    // the estimates are the direct run's.
    assert!(lost > 0 || r.same_estimates);
    let _ = std::fs::remove_dir_all(&r.dir);
}
