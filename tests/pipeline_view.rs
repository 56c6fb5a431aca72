//! The live view (docs/view.md) on a real `demo --view`: Debian's chromium, headless, driven
//! by playwright-core (`tests/browser/`, `npm ci` there) opens the page, which must plot
//! every instant of every series with the ±2σ bands drawn and say "run ended"; a screenshot
//! lands in the test's scratch directory. Without chromium, node or the npm packages the
//! browser test says so on one line and passes, unless `REQUIRE_BROWSER=1` (`.ci/run` sets
//! it after installing them). The hostile-client test needs no browser.

mod pipeline_common;
#[path = "skip_log.rs"]
mod skip_log;

use pipeline_common as common;
use pipeline_common::{csv, scratch, Proc};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::time::Duration;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// chromium and node with playwright-core, or `None` and one line saying what is missing.
fn browser() -> Option<(PathBuf, PathBuf)> {
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    let node_ok = std::process::Command::new("node")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    let pw = repo().join("tests/browser/node_modules/playwright-core");
    let missing = if !Path::new(&chromium).exists() {
        format!("{chromium} (apt-get install chromium)")
    } else if !node_ok {
        "node (apt-get install nodejs)".to_string()
    } else if !pw.exists() {
        "playwright-core (npm ci in tests/browser)".to_string()
    } else {
        return Some((
            PathBuf::from(chromium),
            repo().join("tests/browser/view_check.mjs"),
        ));
    };
    assert!(
        std::env::var("REQUIRE_BROWSER").as_deref() != Ok("1"),
        "REQUIRE_BROWSER=1 but {missing} is missing"
    );
    skip_log::skipped(
        &skip_log::current_test("browser"),
        &format!("the browser test needs {missing} (REQUIRE_BROWSER=1 makes it fail)"),
    );
    None
}

/// The view's address from the demo's stderr.
fn view_addr(demo: &Proc) -> String {
    demo.wait_for_stderr("view: http://", 60);
    let err = demo.err();
    let line = err
        .lines()
        .find(|l| l.starts_with("view: http://"))
        .unwrap();
    line.trim_start_matches("view: http://")
        .trim_end_matches('/')
        .to_string()
}

fn start_demo(dir: &Path, name: &str, steps: u32, rate: u32, extra: &[&str]) -> Proc {
    let out = dir.join("out");
    let (steps, rate) = (steps.to_string(), rate.to_string());
    let prefix = common::prefix(name);
    let mut args = vec![
        "demo",
        "--steps",
        &steps,
        "--rate",
        &rate,
        "--wait",
        "block",
        "--prefix",
        &prefix,
        "--quiet",
        "--out",
        out.to_str().unwrap(),
        "--view",
        "--view-addr",
        "127.0.0.1:0",
    ];
    args.extend_from_slice(extra);
    Proc::start(dir, name, &args)
}

/// A `demo --view` of N instants at 100 Hz, nothing thinned (`--view-points-per-s`): after the run the page holds N points of the truth and of every
/// estimator the run's CSV names (the truth where the CSV has it), draws one band per estimator and component, and says
/// "run ended".
#[test]
fn the_page_plots_every_instant_with_its_bands() {
    let Some((chromium, script)) = browser() else {
        return;
    };
    let dir = scratch("view-browser");
    let n = 300u32;
    // No thinning whatever the scheduler does to the view's frames (a late frame holds more
    // instants; decimation has its own unit tests in view/decimate.rs).
    let mut demo = start_demo(
        &dir,
        "view-demo",
        n,
        100,
        &["--view-linger", "120", "--view-points-per-s", "100000"],
    );
    let addr = view_addr(&demo);
    let shot = dir.join("view.png");
    let o = std::process::Command::new("node")
        .arg(&script)
        .arg(format!("http://{addr}/"))
        .arg(&shot)
        .env("CHROMIUM", &chromium)
        .current_dir(repo().join("tests/browser"))
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "node: {}\n{}",
        String::from_utf8_lossy(&o.stderr),
        demo.err()
    );
    let state: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    demo.signal(libc::SIGINT);
    let status = demo.wait(60);
    assert!(status.success(), "demo: {status}\n{}", demo.err());

    assert_eq!(state["errors"], serde_json::json!([]), "page errors");
    assert_eq!(state["state"], "run ended");
    assert_eq!(state["instants"], u64::from(n));
    let (head, rows) = csv(&dir.join("out/estimates.csv"));
    assert_eq!(rows.len(), n as usize);
    let nx = head.iter().filter(|h| h.starts_with("truth_")).count();
    let names: Vec<String> = head[2 + nx..]
        .chunks(nx)
        .map(|c| c[0].trim_end_matches("_0").to_string())
        .collect();
    assert_eq!(state["names"], serde_json::json!(names));
    assert_eq!(state["nx"], nx);
    assert_eq!(state["points"]["k"], u64::from(n), "{state}");
    // The truth where the run had it (its CSV's rows with a truth).
    let with_truth = rows.iter().filter(|r| !r[2].is_nan()).count();
    assert_eq!(state["points"]["truth"], with_truth, "{state}");
    for name in &names {
        assert_eq!(state["points"][name], u64::from(n), "{name}: {state}");
    }
    // Every estimator of the occlusion preset publishes a covariance: a band per estimator
    // and component.
    assert_eq!(state["bandsDrawn"], names.len() * nx, "{state}");
    let png = std::fs::read(&shot).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    eprintln!("screenshot: {}", shot.display());
}

/// Hostile clients of the view: an unknown path is 404, a malformed request is answered or
/// closed, a websocket that never reads stays connected while a 1 kHz run completes every
/// instant; the page is still served afterwards.
#[test]
fn hostile_clients_do_not_stop_the_view_or_the_run() {
    let dir = scratch("view-hostile");
    let n = 3000u32;
    let mut demo = start_demo(&dir, "view-hostile", n, 1000, &["--view-linger", "60"]);
    let addr = view_addr(&demo);
    let get = |path: &str| -> String {
        let mut s = TcpStream::connect(&addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        write!(
            s,
            "GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut r = String::new();
        let _ = s.read_to_string(&mut r);
        r
    };
    assert!(get("/nope").starts_with("HTTP/1.1 404"));
    // Garbage: whatever the answer, the server lives on.
    {
        let mut s = TcpStream::connect(&addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        s.write_all(&[0xff; 4096]).unwrap();
        let mut sink = Vec::new();
        let _ = s.read_to_end(&mut sink);
    }
    // A websocket that upgrades and then never reads a byte.
    let mut stalled = TcpStream::connect(&addr).unwrap();
    write!(
        stalled,
        "GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    .unwrap();
    demo.wait_for_stderr("view: the run ended", 300);
    let page = get("/");
    assert!(page.starts_with("HTTP/1.1 200"), "{page}");
    assert!(page.contains("estpipe live view"));
    assert!(get("/uPlot.iife.min.js").starts_with("HTTP/1.1 200"));
    demo.signal(libc::SIGINT);
    let status = demo.wait(60);
    assert!(status.success(), "demo: {status}\n{}", demo.err());
    let (_, rows) = csv(&dir.join("out/estimates.csv"));
    assert_eq!(rows.len(), n as usize);
    drop(stalled);
}

/// The websocket upgrade of `/ws` on `s`; the server's 101 read up to its blank line.
fn upgrade(s: &mut TcpStream) {
    write!(
        s,
        "GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    .unwrap();
    let mut head = Vec::new();
    let mut b = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        s.read_exact(&mut b).unwrap();
        head.push(b[0]);
        assert!(head.len() < 4096, "no end of the upgrade's answer");
    }
    let head = String::from_utf8_lossy(&head);
    assert!(head.starts_with("HTTP/1.1 101"), "{head}");
}

/// The next message of the server (unmasked, unfragmented: what the view sends): its opcode
/// and payload.
fn ws_message(s: &mut TcpStream) -> std::io::Result<(u8, Vec<u8>)> {
    let mut h = [0u8; 2];
    s.read_exact(&mut h)?;
    let len = match h[1] & 0x7f {
        126 => {
            let mut l = [0u8; 2];
            s.read_exact(&mut l)?;
            u64::from(u16::from_be_bytes(l))
        }
        127 => {
            let mut l = [0u8; 8];
            s.read_exact(&mut l)?;
            u64::from_be_bytes(l)
        }
        l => u64::from(l),
    };
    assert_eq!(h[1] & 0x80, 0, "a server's frame is never masked");
    assert!(len <= 64 << 20, "a frame of {len} bytes");
    let mut payload = vec![0u8; len as usize];
    s.read_exact(&mut payload)?;
    Ok((h[0] & 0x0f, payload))
}

/// What a page that reads every frame saw until the state "run ended".
#[derive(Debug, Default)]
struct Seen {
    frames: u64,
    points: u64,
    /// Points received in frames after one that said a page had been dropped.
    points_after_drop: u64,
    last: serde_json::Value,
}

/// Reads the view's frames on a fresh websocket until one says "run ended" (or 120 s pass).
fn read_until_ended(addr: &str) -> Seen {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    upgrade(&mut s);
    let mut seen = Seen::default();
    loop {
        let (op, payload) = ws_message(&mut s).unwrap_or_else(|e| panic!("{e}: {seen:?}"));
        match op {
            1 => {}
            8 => panic!("the server closed the reading page: {seen:?}"),
            _ => continue,
        }
        let v: serde_json::Value = serde_json::from_slice(&payload).unwrap();
        if v.get("reset").is_some() {
            continue;
        }
        seen.frames += 1;
        let points = v["points"].as_array().map_or(0, Vec::len) as u64;
        seen.points += points;
        if v["pages_dropped"].as_u64().unwrap_or(0) > 0 {
            seen.points_after_drop += points;
        }
        let ended = v["state"] == "run ended";
        seen.last = v;
        if ended {
            return seen;
        }
    }
}

/// A page that stops reading is dropped, never waited for (docs/view.md, "Hostile pages"):
/// a websocket whose socket has a tiny receive buffer (set before it connects, so that the
/// loopback connection's window stays small) upgrades and never reads a byte, while a second
/// page reads every frame of a 1 kHz `demo --view` that sends every instant. The server must
/// drop the first (its stderr line, and the frames' `pages_dropped`) and close it; the reading
/// page must get every instant, some after the drop; the run must complete every instant.
#[test]
fn a_page_that_stops_reading_is_dropped_while_a_reading_page_keeps_up() {
    use socket2::{Domain, Socket, Type};
    let dir = scratch("view-stalled");
    let n = 15000u32;
    let mut demo = start_demo(
        &dir,
        "view-stalled",
        n,
        1000,
        &["--view-linger", "60", "--view-points-per-s", "100000"],
    );
    let addr = view_addr(&demo);
    let stalled = Socket::new(Domain::IPV4, Type::STREAM, None).unwrap();
    // The kernel's minimum (it doubles what it is given and has a floor of its own).
    stalled.set_recv_buffer_size(1024).unwrap();
    let sockaddr: std::net::SocketAddr = addr.parse().unwrap();
    stalled.connect(&sockaddr.into()).unwrap();
    let mut stalled: TcpStream = stalled.into();
    upgrade(&mut stalled);
    let reader = {
        let addr = addr.clone();
        std::thread::spawn(move || read_until_ended(&addr))
    };
    let seen = reader.join().unwrap();
    demo.wait_for_stderr("view: the run ended", 300);
    let err = demo.err();
    let drops = err.matches("view: dropped a page that").count();
    assert_eq!(drops, 1, "the stalled page dropped once:\n{err}");
    assert_eq!(seen.last["pages_dropped"], 1, "{:?}", seen.last);
    assert_eq!(seen.last["instants"], u64::from(n), "{:?}", seen.last);
    // Nothing thinned (`--view-points-per-s`): every instant reached the reading page.
    assert_eq!(seen.points, u64::from(n), "{seen:?}");
    assert!(
        seen.points_after_drop > 0,
        "the drop came after the run: {seen:?}"
    );
    // The server closed the stalled page: what was on its way drains, then the end.
    stalled
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let mut sink = [0u8; 65536];
    loop {
        match stalled.read(&mut sink) {
            Ok(0) => break,
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => break,
            Err(e) => panic!("the stalled page is still connected ({e})"),
        }
    }
    demo.signal(libc::SIGINT);
    let status = demo.wait(60);
    assert!(status.success(), "demo: {status}\n{}", demo.err());
    let (_, rows) = csv(&dir.join("out/estimates.csv"));
    assert_eq!(rows.len(), n as usize);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/report.json")).unwrap())
            .unwrap();
    eprintln!(
        "reading page: {} frames, {} points ({} after the drop); end-to-end p50 {} µs",
        seen.frames, seen.points, seen.points_after_drop, report["latency"]["end_to_end"]["p50_us"]
    );
}
