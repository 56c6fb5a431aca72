//! The C client library of the estimation pipeline: publish slots to `ipc-runner run` and
//! receive its estimates from C, through the C ABI declared in `clients/c/estpipe.h`.
//!
//! Why this crate and not iceoryx2's own C binding: iceoryx2 0.10's C binding is built with
//! cmake from the iceoryx2 repository; it is not on crates.io (`iceoryx2-ffi` there stops at
//! 0.4.1, `iceoryx2-ffi-c` is not published), so it cannot be built from the registries the
//! product builds from. This crate is built by cargo with the workspace and exposes only what
//! a sensor publisher and an estimate subscriber need, with the product's own code behind it:
//!
//! * the services are opened by [`estpipe_wire::slot_service`] and
//!   [`estpipe_wire::estimate_service`] with the contract's QoS (`docs/wire.md`, "Services
//!   and QoS"), refusals in the product's words;
//! * a slot is sent by `channel-sim`'s [`SlotSender`] (`RetryUntilDelivered` with the
//!   back-pressure [`Gate`], sent again until every subscriber has it: `docs/wire.md`,
//!   "Sending a slot");
//! * a publisher waits for a subscriber before its first slot
//!   ([`channel_sim::publisher::wait_for_subscriber`]) and lingers until it detached;
//! * a slot is checked by [`Slot::fault`] against the stream header before it is sent, the
//!   header by [`StreamHeader::validate`].
//!
//! Every function returns a status code (`ESTPIPE_OK`, …); a null or misaligned pointer, a
//! string that is not UTF-8 and every failure give a negative code and a message
//! ([`estpipe_last_error`]); a panic is caught at the boundary (`ESTPIPE_ERR_PANIC`), never
//! unwound into C. `unsafe` is only where a C pointer is read or written, each with its reason.

use channel_sim::backpressure::{Gate, Mode};
use channel_sim::publisher::{wait_for_subscriber, SlotSender, Stop};
use estpipe_wire::services::SlotService;
use estpipe_wire::{self as wire, Estimate, Slot, StreamHeader, SLOT_DATA};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use std::cell::RefCell;
use std::ffi::{c_char, c_int, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Done.
pub const ESTPIPE_OK: c_int = 0;
/// Nothing within the timeout: no subscriber (`estpipe_publisher_open`), no estimate
/// (`estpipe_receive`).
pub const ESTPIPE_TIMEOUT: c_int = 1;
/// A slot did not reach every subscriber: the subscriber is gone (cleaned up after its
/// death), or the send's timeout ran out.
pub const ESTPIPE_GAVE_UP: c_int = 2;
/// SIGINT, SIGTERM or SIGHUP arrived (see `estpipe_stop_requested`): the slot was not sent,
/// or the wait ended.
pub const ESTPIPE_STOPPED: c_int = 3;
/// A null pointer where one is required.
pub const ESTPIPE_ERR_NULL: c_int = -1;
/// A bad argument: a misaligned pointer, a string that is not UTF-8, a header or slot
/// outside the contract.
pub const ESTPIPE_ERR_ARG: c_int = -2;
/// iceoryx2 failed (node, port, send, receive).
pub const ESTPIPE_ERR_IPC: c_int = -3;
/// A panic inside the library, caught at the boundary.
pub const ESTPIPE_ERR_PANIC: c_int = -4;
/// A peer outside the contract: a service created with another QoS or payload, an estimate
/// of another wire version.
pub const ESTPIPE_ERR_CONTRACT: c_int = -5;

thread_local! {
    /// The message of the last failure on this thread ([`estpipe_last_error`]).
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

/// A failure: its status code and its one-line message.
struct Fail(c_int, String);

impl Fail {
    fn null(what: &str) -> Self {
        Self(ESTPIPE_ERR_NULL, format!("{what} is a null pointer"))
    }
    fn arg(msg: impl Into<String>) -> Self {
        Self(ESTPIPE_ERR_ARG, msg.into())
    }
    fn ipc(msg: impl Into<String>) -> Self {
        Self(ESTPIPE_ERR_IPC, msg.into())
    }
}

impl From<wire::ContractError> for Fail {
    fn from(e: wire::ContractError) -> Self {
        Self(ESTPIPE_ERR_CONTRACT, e.to_string())
    }
}

fn set_error(msg: &str) {
    // A message with a NUL byte (never ours) is cut there rather than lost.
    let c = CString::new(msg.split('\0').next().unwrap_or_default()).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
}

/// Runs `f` with the error message cleared; its failure or panic becomes the status code
/// and the message: nothing unwinds into C.
fn guard(f: impl FnOnce() -> Result<c_int, Fail>) -> c_int {
    set_error("");
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(code)) => code,
        Ok(Err(Fail(code, msg))) => {
            set_error(&msg);
            code
        }
        Err(panic) => {
            let why = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            set_error(&format!("internal error (panic): {why}"));
            ESTPIPE_ERR_PANIC
        }
    }
}

/// `ptr` as a reference to `T`, refusing null and misaligned pointers.
///
/// # Safety
/// A non-null, aligned `ptr` must point to a valid `T` that lives and is not written by
/// anyone else while the reference is used (the caller of the C function promises it).
unsafe fn arg<'a, T>(ptr: *const T, what: &str) -> Result<&'a T, Fail> {
    if ptr.is_null() {
        return Err(Fail::null(what));
    }
    if !ptr.is_aligned() {
        return Err(Fail::arg(format!("{what} is not aligned for its type")));
    }
    // SAFETY: non-null and aligned checked above; validity is the caller's promise.
    Ok(unsafe { &*ptr })
}

/// `ptr` as a mutable reference, with [`arg`]'s checks.
///
/// # Safety
/// As [`arg`], and nobody else reads or writes `*ptr` while the reference is used.
unsafe fn arg_mut<'a, T>(ptr: *mut T, what: &str) -> Result<&'a mut T, Fail> {
    if ptr.is_null() {
        return Err(Fail::null(what));
    }
    if !ptr.is_aligned() {
        return Err(Fail::arg(format!("{what} is not aligned for its type")));
    }
    // SAFETY: non-null and aligned checked above; validity and exclusivity are the
    // caller's promise.
    Ok(unsafe { &mut *ptr })
}

/// A C string argument as UTF-8.
///
/// # Safety
/// A non-null `ptr` must point to a NUL-terminated string.
unsafe fn str_arg<'a>(ptr: *const c_char, what: &str) -> Result<&'a str, Fail> {
    if ptr.is_null() {
        return Err(Fail::null(what));
    }
    // SAFETY: non-null; NUL termination is the caller's promise.
    let c = unsafe { CStr::from_ptr(ptr) };
    c.to_str()
        .map_err(|e| Fail::arg(format!("{what} is not UTF-8 ({e})")))
}

/// `timeout_ms` as a duration.
fn ms(timeout_ms: u32) -> Duration {
    Duration::from_millis(u64::from(timeout_ms))
}

/// The process's node for the C client, with dead nodes cleaned up (a killed predecessor
/// leaves its ports registered) and the product's signal handling installed.
fn node() -> Result<Node<ipc::Service>, Fail> {
    set_log_level_from_env_or(LogLevel::Error);
    // As every process of the product: SIGINT/SIGTERM/SIGHUP set a flag that a blocked send
    // or a wait sees within a slice (docs/security.md, "Signals").
    estpipe_process::signal::install();
    let node = estpipe_process::node::create("estpipe-c")
        .map_err(|e| Fail(ESTPIPE_ERR_IPC, format!("{e:#}")))?;
    let _ = node.try_cleanup_dead_nodes();
    Ok(node)
}

/// The message of the last failure of a call on this thread ("" after a success). Valid
/// until the next `estpipe_*` call on this thread.
#[no_mangle]
pub extern "C" fn estpipe_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

/// `CLOCK_MONOTONIC` in ns: the clock of every timestamp of the contract (`send_ns`,
/// `stream_start_ns`).
#[no_mangle]
pub extern "C" fn estpipe_monotonic_ns() -> u64 {
    catch_unwind(wire::monotonic_ns).unwrap_or(0)
}

/// 1 once SIGINT, SIGTERM or SIGHUP arrived after a publisher or subscriber was opened, else 0.
#[no_mangle]
pub extern "C" fn estpipe_stop_requested() -> c_int {
    catch_unwind(estpipe_process::signal::termination_requested).map_or(0, c_int::from)
}

/// Parses the JSON line of `ipc-runner stream-header` into `*out`, with the checks of
/// `clients/python` (`StreamHeader.from_json`) and the runner's [`StreamHeader::validate`].
///
/// # Safety
/// `json` is null or a NUL-terminated string; `out` is null or points to a writable
/// `estpipe_StreamHeader`.
#[no_mangle]
pub unsafe extern "C" fn estpipe_header_from_json(
    json: *const c_char,
    out: *mut StreamHeader,
) -> c_int {
    guard(|| {
        // SAFETY: the caller's promise above.
        let text = unsafe { str_arg(json, "json") }?;
        // SAFETY: the caller's promise above.
        let out = unsafe { arg_mut(out, "out") }?;
        *out = header_from_json(text).map_err(|e| Fail::arg(format!("stream header: {e}")))?;
        Ok(ESTPIPE_OK)
    })
}

fn header_from_json(text: &str) -> Result<StreamHeader, String> {
    let v: serde_json::Value =
        serde_json::from_str(text.trim()).map_err(|e| format!("not JSON ({e})"))?;
    let obj = v.as_object().ok_or("expected a JSON object")?;
    let get = |key: &str| obj.get(key).ok_or(format!("missing {key:?}"));
    let uint = |key: &str, max: u64| -> Result<u64, String> {
        get(key)?
            .as_u64()
            .filter(|&n| n <= max)
            .ok_or(format!("{key} is not an integer 0..={max}"))
    };
    let version = uint("wire_version", u64::from(u32::MAX))? as u32;
    if version != wire::WIRE_VERSION {
        return Err(format!(
            "wire_version {version}, but this library speaks {}",
            wire::WIRE_VERSION
        ));
    }
    let nodes = uint("nodes", wire::MAX_NODES as u64)? as usize;
    let nx = uint("nx", wire::MAX_NX as u64)? as usize;
    let ny = get("ny")?
        .as_array()
        .filter(|a| a.len() == nodes)
        .ok_or(format!("ny must list {nodes} entries"))?
        .iter()
        .map(|n| {
            n.as_u64()
                .filter(|&n| n <= wire::MAX_NY as u64)
                .map(|n| n as usize)
                .ok_or(format!("ny entries must be 0..={}", wire::MAX_NY))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let model = get("model")?
        .as_str()
        .and_then(|s| s.strip_prefix("0x"))
        .and_then(|s| u64::from_str_radix(s, 16).ok())
        .ok_or("model is not a 0x… 64-bit hex string")?;
    let name = get("scenario")?
        .as_str()
        .ok_or("scenario must be a string")?;
    if name.len() > wire::header::SCENARIO_NAME_LEN {
        return Err(format!(
            "scenario name is {} bytes, at most {}",
            name.len(),
            wire::header::SCENARIO_NAME_LEN
        ));
    }
    let h = StreamHeader::new(name, nodes, nx, &ny, model);
    h.validate().map_err(|e| e.to_string())?;
    Ok(h)
}

/// A publisher of one sensor side's slots on `<prefix>/slots` (`estpipe_publisher` in C).
#[derive(Debug)]
pub struct EstpipePublisher {
    sender: SlotSender,
    notifier: Notifier<ipc::Service>,
    gate: Arc<Gate>,
    service: Arc<SlotService>,
    node: Arc<Node<ipc::Service>>,
    header: StreamHeader,
}

/// Opens `<prefix>/slots` (and `<prefix>/slots-ready`) with the contract's QoS, creates a
/// publisher whose every slot carries `*header`, and waits up to `timeout_ms` (0: for ever)
/// for a subscriber (the runner): slots sent before one exists are lost.
///
/// Returns `ESTPIPE_OK` with `*out` set, `ESTPIPE_TIMEOUT` (no subscriber), `ESTPIPE_STOPPED`
/// or a negative code; `*out` is null unless `ESTPIPE_OK`.
///
/// # Safety
/// `prefix` is null or a NUL-terminated string; `header` is null or points to an
/// `estpipe_StreamHeader`; `out` is null or points to a writable `estpipe_publisher *`.
#[no_mangle]
pub unsafe extern "C" fn estpipe_publisher_open(
    prefix: *const c_char,
    header: *const StreamHeader,
    timeout_ms: u32,
    out: *mut *mut EstpipePublisher,
) -> c_int {
    guard(|| {
        // SAFETY: the caller's promise above.
        let out = unsafe { arg_mut(out, "out") }?;
        *out = std::ptr::null_mut();
        // SAFETY: the caller's promise above.
        let prefix = unsafe { str_arg(prefix, "prefix") }?;
        // SAFETY: the caller's promise above.
        let header = *unsafe { arg(header, "header") }?;
        header.validate()?;
        let node = Arc::new(node()?);
        let service = Arc::new(wire::slot_service(&node, prefix)?);
        let ready = wire::ready_event_service(&node, prefix)?;
        let gate = Gate::new();
        // Data slots are sent until every subscriber has them (channel-sim's `--backpressure
        // block`): a C publisher paces itself and loses nothing.
        gate.set_mode(Mode::Block);
        let since = std::time::SystemTime::now() - Duration::from_secs(1);
        let publisher = service
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
            .set_backpressure_handler(gate.handler())
            .create()
            .map_err(|e| {
                Fail::ipc(estpipe_process::shm_leftovers::publisher_error(
                    e,
                    node.config(),
                    since,
                    &format!("{prefix}/slots"),
                    &format!(
                        "are {} publishers already running with this prefix?",
                        wire::MAX_NODES
                    ),
                ))
            })?;
        let notifier = ready
            .notifier_builder()
            .default_event_id(wire::READY_EVENT)
            .create()
            .map_err(|e| Fail::ipc(format!("cannot notify on {prefix}/slots-ready: {e:?}")))?;
        await_subscriber(&node, &gate, &service, prefix, timeout_ms)?;
        let sender = SlotSender::new(
            publisher,
            header,
            Arc::clone(&gate),
            Arc::clone(&node),
            Arc::clone(&service),
        );
        *out = Box::into_raw(Box::new(EstpipePublisher {
            sender,
            notifier,
            gate,
            service,
            node,
            header,
        }));
        Ok(ESTPIPE_OK)
    })
}

/// Waits up to `timeout_ms` (0: for ever) for a subscriber on `<prefix>/slots`: the runner,
/// without which the publisher's slots would be lost.
fn await_subscriber(
    node: &Node<ipc::Service>,
    gate: &Gate,
    service: &SlotService,
    prefix: &str,
    timeout_ms: u32,
) -> Result<(), Fail> {
    let n_subs = || service.dynamic_config().number_of_subscribers();
    let timeout_s = f64::from(timeout_ms) / 1000.0;
    match wait_for_subscriber(node, gate, n_subs, timeout_s) {
        Ok(true) => Ok(()),
        Ok(false) => Err(Fail(
            ESTPIPE_TIMEOUT,
            format!(
                "no subscriber on {prefix}/slots within {timeout_s} s (start `ipc-runner \
                 run --prefix {prefix}` first)"
            ),
        )),
        Err(Stop::Signal) => Err(Fail(
            ESTPIPE_STOPPED,
            "stopped by signal while waiting for a subscriber".into(),
        )),
    }
}

/// Sends `*slot` with the publisher's stream header until every subscriber has it
/// (`docs/wire.md`, "Sending a slot"): a full queue blocks, a subscriber not yet connected is
/// sent the slot again, a subscriber that does not read for 2 s is dropped from the wait.
/// `timeout_ms` bounds the send (0: none; then only a dead subscriber, cleaned up, or a stop
/// signal ends it). An END/ABORT marker is sent even after a stop signal, until `timeout_ms`
/// (give one), and gets its `send_ns` here.
///
/// The slot is checked first against the header (`Slot::fault`: version, node, seq = k − 1,
/// ny, a finite measurement, …, a delivered `y` 0 past `ny`): `ESTPIPE_ERR_ARG` names what is
/// wrong and nothing is sent.
/// Returns `ESTPIPE_OK`, `ESTPIPE_GAVE_UP`, `ESTPIPE_STOPPED` (a data slot not sent) or a
/// negative code.
///
/// # Safety
/// `publisher` is null or an open publisher not used by another thread meanwhile; `slot` is
/// null or points to an `estpipe_Slot`.
#[no_mangle]
pub unsafe extern "C" fn estpipe_publish(
    publisher: *mut EstpipePublisher,
    slot: *const Slot,
    timeout_ms: u32,
) -> c_int {
    guard(|| {
        // SAFETY: the caller's promise above.
        let p = unsafe { arg_mut(publisher, "publisher") }?;
        // SAFETY: the caller's promise above.
        let slot = *unsafe { arg(slot, "slot") }?;
        if let Some(why) = refusal(&slot, &p.header) {
            return Err(Fail::arg(format!(
                "slot k = {} of node {}: {why}",
                slot.k, slot.node
            )));
        }
        let data = slot.kind == SLOT_DATA;
        p.gate
            .set_mode(if data { Mode::Block } else { Mode::Final });
        let give_up = (timeout_ms > 0).then(|| Instant::now() + ms(timeout_ms));
        // A marker without a timeout would wait for ever after a stop: 5 s, channel-sim's
        // default --linger.
        let give_up = give_up.or((!data).then(|| Instant::now() + Duration::from_secs(5)));
        let sent = p
            .sender
            .send(slot, give_up)
            .map_err(|e| Fail::ipc(format!("cannot send slot k = {}: {e:#}", slot.k)))?;
        Ok(match sent {
            channel_sim::publisher::Sent::Done => ESTPIPE_OK,
            channel_sim::publisher::Sent::GaveUp => ESTPIPE_GAVE_UP,
            channel_sim::publisher::Sent::Stopped => ESTPIPE_STOPPED,
        })
    })
}

/// Why `slot` breaks the contract for a stream of `header`, if it does: what the runner would
/// refuse (`Slot::fault`), and a delivered measurement not 0 past its `ny` (docs/wire.md,
/// Slot: "entries ≥ `ny` are 0"), which the runner would ignore but a C caller should hear of.
fn refusal(slot: &Slot, header: &StreamHeader) -> Option<String> {
    let nodes = header.nodes;
    if let Some(f) = slot.fault(nodes, &header.ny[..usize::from(nodes)]) {
        return Some(format!(
            "{f} (docs/wire.md, What the runner does with a bad slot)"
        ));
    }
    let ny = usize::from(slot.ny).min(wire::MAX_NY);
    let past = slot.y[ny..].iter().position(|v| *v != 0.0)?;
    (slot.kind == SLOT_DATA && slot.delivered == 1).then(|| {
        format!(
            "y[{}] = {} past ny = {ny} must be 0 (docs/wire.md, Slot)",
            ny + past,
            slot.y[ny + past]
        )
    })
}

/// Notifies `<prefix>/slots-ready` (event `ESTPIPE_READY_EVENT`): call it after each
/// instant's slots, as every publisher of the product does.
///
/// # Safety
/// `publisher` is null or an open publisher not used by another thread meanwhile.
#[no_mangle]
pub unsafe extern "C" fn estpipe_instant_done(publisher: *mut EstpipePublisher) -> c_int {
    guard(|| {
        // SAFETY: the caller's promise above.
        let p = unsafe { arg_mut(publisher, "publisher") }?;
        p.notifier
            .notify()
            .map_err(|e| Fail::ipc(format!("cannot notify slots-ready: {e:?}")))?;
        Ok(ESTPIPE_OK)
    })
}

/// Subscribers of the publisher's slot service now (≥ 0), or a negative code.
///
/// # Safety
/// `publisher` is null or an open publisher not used by another thread meanwhile.
#[no_mangle]
pub unsafe extern "C" fn estpipe_publisher_subscribers(publisher: *mut EstpipePublisher) -> c_int {
    guard(|| {
        // SAFETY: the caller's promise above.
        let p = unsafe { arg_mut(publisher, "publisher") }?;
        Ok(c_int::try_from(p.sender.subscribers()).unwrap_or(c_int::MAX))
    })
}

/// Waits up to `linger_ms` until the subscribers have detached (the runner reads the last
/// slots from this publisher's memory, so the publisher stays until then; one that does not
/// read is not waited for), then closes the publisher and frees it. Null does nothing.
///
/// # Safety
/// `publisher` is null or an open publisher, not used again after this call.
#[no_mangle]
pub unsafe extern "C" fn estpipe_publisher_close(
    publisher: *mut EstpipePublisher,
    linger_ms: u32,
) -> c_int {
    guard(|| {
        if publisher.is_null() {
            return Ok(ESTPIPE_OK);
        }
        // SAFETY: a pointer from `estpipe_publisher_open` (Box::into_raw), closed once.
        let p = unsafe { Box::from_raw(publisher) };
        let give_up = Instant::now() + ms(linger_ms);
        let mut last_cleanup = Instant::now();
        while p.service.dynamic_config().number_of_subscribers() > p.gate.unread_receivers()
            && Instant::now() < give_up
        {
            if last_cleanup.elapsed() > Duration::from_millis(100) {
                let _ = p.node.try_cleanup_dead_nodes();
                last_cleanup = Instant::now();
            }
            if channel_sim::publisher::wait(&p.node, &p.gate, Duration::from_millis(2)).is_err() {
                break;
            }
        }
        drop(p);
        Ok(ESTPIPE_OK)
    })
}

/// A subscriber of `<prefix>/estimates` (`estpipe_subscriber` in C).
#[derive(Debug)]
pub struct EstpipeSubscriber {
    subscriber: Subscriber<ipc::Service, Estimate, ()>,
    node: Node<ipc::Service>,
    prefix: String,
}

/// Opens `<prefix>/estimates` with the contract's QoS and subscribes. A subscriber that
/// connects while the runner runs first gets the newest estimates (the service's history).
///
/// # Safety
/// `prefix` is null or a NUL-terminated string; `out` is null or points to a writable
/// `estpipe_subscriber *`.
#[no_mangle]
pub unsafe extern "C" fn estpipe_subscriber_open(
    prefix: *const c_char,
    out: *mut *mut EstpipeSubscriber,
) -> c_int {
    guard(|| {
        // SAFETY: the caller's promise above.
        let out = unsafe { arg_mut(out, "out") }?;
        *out = std::ptr::null_mut();
        // SAFETY: the caller's promise above.
        let prefix = unsafe { str_arg(prefix, "prefix") }?;
        let node = node()?;
        let service = wire::estimate_service(&node, prefix)?;
        let subscriber = service
            .subscriber_builder()
            .create()
            .map_err(|e| Fail::ipc(format!("cannot subscribe to {prefix}/estimates: {e:?}")))?;
        *out = Box::into_raw(Box::new(EstpipeSubscriber {
            subscriber,
            node,
            prefix: prefix.to_string(),
        }));
        Ok(ESTPIPE_OK)
    })
}

/// Copies the next estimate into `*out`, waiting up to `timeout_ms` (0: only looks) in short
/// waits (a long sleep would add its wake-up to the latency). Returns `ESTPIPE_OK`,
/// `ESTPIPE_TIMEOUT`, `ESTPIPE_STOPPED`, `ESTPIPE_ERR_CONTRACT` (an estimate of another wire
/// version: `*out` holds it all the same) or a negative code.
///
/// # Safety
/// `subscriber` is null or an open subscriber not used by another thread meanwhile; `out` is
/// null or points to a writable `estpipe_Estimate`.
#[no_mangle]
pub unsafe extern "C" fn estpipe_receive(
    subscriber: *mut EstpipeSubscriber,
    out: *mut Estimate,
    timeout_ms: u32,
) -> c_int {
    guard(|| {
        // SAFETY: the caller's promise above.
        let s = unsafe { arg_mut(subscriber, "subscriber") }?;
        // SAFETY: the caller's promise above.
        let out = unsafe { arg_mut(out, "out") }?;
        let end = Instant::now() + ms(timeout_ms);
        loop {
            let got = s.subscriber.receive().map_err(|e| {
                Fail::ipc(format!("cannot receive from {}/estimates: {e:?}", s.prefix))
            })?;
            if let Some(sample) = got {
                *out = *sample.payload();
                if out.version != wire::WIRE_VERSION {
                    return Err(Fail(
                        ESTPIPE_ERR_CONTRACT,
                        format!(
                            "an estimate of wire version {}, this library speaks {} \
                             (docs/wire.md, Versioning)",
                            out.version,
                            wire::WIRE_VERSION
                        ),
                    ));
                }
                return Ok(ESTPIPE_OK);
            }
            if estpipe_process::signal::termination_requested() {
                return Ok(ESTPIPE_STOPPED);
            }
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(ESTPIPE_TIMEOUT);
            }
            // An error is an interrupted wait: the loop looks at the stop flag.
            let _ = s.node.wait(left.min(Duration::from_micros(50)));
        }
    })
}

/// Closes the subscriber and frees it. Null does nothing.
///
/// # Safety
/// `subscriber` is null or an open subscriber, not used again after this call.
#[no_mangle]
pub unsafe extern "C" fn estpipe_subscriber_close(subscriber: *mut EstpipeSubscriber) -> c_int {
    guard(|| {
        if !subscriber.is_null() {
            // SAFETY: a pointer from `estpipe_subscriber_open` (Box::into_raw), closed once.
            drop(unsafe { Box::from_raw(subscriber) });
        }
        Ok(ESTPIPE_OK)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_header_json_of_stream_header_parses() {
        let h = header_from_json(
            r#"{"wire_version":6,"scenario":"linear","nodes":1,"nx":2,"ny":[1],"model":"0x00000000000000ff"}"#,
        )
        .unwrap();
        assert_eq!((h.nodes, h.nx, h.ny[0], h.model), (1, 2, 1, 0xff));
        assert_eq!(h.scenario_name(), "linear");
        for bad in [
            "",
            "[]",
            r#"{"wire_version":5,"scenario":"a","nodes":1,"nx":2,"ny":[1],"model":"0x1"}"#,
            r#"{"wire_version":6,"scenario":"a","nodes":2,"nx":2,"ny":[1],"model":"0x1"}"#,
            r#"{"wire_version":6,"scenario":"a","nodes":1,"nx":9,"ny":[1],"model":"0x1"}"#,
            r#"{"wire_version":6,"scenario":"a","nodes":1,"nx":2,"ny":[1],"model":"12"}"#,
        ] {
            assert!(header_from_json(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_delivered_measurement_not_zero_past_ny_is_refused() {
        let h = StreamHeader::new("linear", 1, 2, &[1], 0);
        let mut obs = wire::Observation::dropped(1, 0, 1, 0);
        (obs.delivered, obs.y[0]) = (true, 0.5);
        let ok = wire::observation::slot_of(&obs, 1, 7, 0, 0, 0);
        assert_eq!(refusal(&ok, &h), None);
        obs.y[2] = 1.0;
        let bad = wire::observation::slot_of(&obs, 1, 7, 0, 0, 0);
        let why = refusal(&bad, &h).expect("refused");
        assert!(why.contains("y[2] = 1 past ny = 1 must be 0"), "{why}");
        // A dropped slot's y is not read: no refusal.
        obs.delivered = false;
        assert_eq!(
            refusal(&wire::observation::slot_of(&obs, 1, 7, 0, 0, 0), &h),
            None
        );
        // What the runner refuses comes first.
        let mut wrong_node = ok;
        wrong_node.node = 3;
        assert!(refusal(&wrong_node, &h).unwrap().contains("bad slot"));
    }

    #[test]
    fn null_pointers_give_an_error_code_not_a_crash() {
        // SAFETY: null pointers are what is tested; none is dereferenced.
        unsafe {
            assert_eq!(
                estpipe_header_from_json(std::ptr::null(), std::ptr::null_mut()),
                ESTPIPE_ERR_NULL
            );
            let msg = CStr::from_ptr(estpipe_last_error()).to_str().unwrap();
            assert!(msg.contains("json"), "{msg}");
            let mut p = std::ptr::null_mut();
            assert_eq!(
                estpipe_publisher_open(std::ptr::null(), std::ptr::null(), 1, &mut p),
                ESTPIPE_ERR_NULL
            );
            assert!(p.is_null());
            assert_eq!(
                estpipe_publish(std::ptr::null_mut(), std::ptr::null(), 0),
                ESTPIPE_ERR_NULL
            );
            assert_eq!(estpipe_instant_done(std::ptr::null_mut()), ESTPIPE_ERR_NULL);
            assert_eq!(estpipe_publisher_close(std::ptr::null_mut(), 0), ESTPIPE_OK);
            let mut s = std::ptr::null_mut();
            assert_eq!(
                estpipe_subscriber_open(std::ptr::null(), &mut s),
                ESTPIPE_ERR_NULL
            );
            assert_eq!(
                estpipe_receive(std::ptr::null_mut(), std::ptr::null_mut(), 0),
                ESTPIPE_ERR_NULL
            );
            assert_eq!(estpipe_subscriber_close(std::ptr::null_mut()), ESTPIPE_OK);
            // Not UTF-8.
            let bad = [0xffu8 as c_char, 0];
            let mut out = StreamHeader::default();
            assert_eq!(
                estpipe_header_from_json(bad.as_ptr(), &mut out),
                ESTPIPE_ERR_ARG
            );
            // Misaligned.
            let mut buf = [0u64; 8];
            let misaligned = (buf.as_mut_ptr() as *mut u8).wrapping_add(1) as *mut StreamHeader;
            let json = c"{}";
            assert_eq!(
                estpipe_header_from_json(json.as_ptr(), misaligned),
                ESTPIPE_ERR_ARG
            );
        }
    }
}
