//! What a failed open means, in one line: iceoryx2 reports `IncompatibleTypes` or
//! `DoesNotSupportRequestedMinBufferSize`; a person (or a Python client's author) needs to
//! know which type or which setting differs and what the contract requires instead. The
//! existing service's static configuration says it, whatever its types.

use crate::error::ContractError;
use crate::qos::PubSubQos;
use crate::WIRE_VERSION;
use iceoryx2::prelude::*;
use iceoryx2::service::static_config::message_type_details::TypeDetail;

/// A type as iceoryx2 compares it: its name, size and alignment.
fn type_of(t: &TypeDetail) -> String {
    format!(
        "'{}' (size {}, align {})",
        t.type_name(),
        t.size(),
        t.alignment()
    )
}

fn type_of_rust<T: ZeroCopySend>() -> String {
    // SAFETY: `type_name` has no preconditions; it is unsafe only to discourage overrides.
    #[allow(unsafe_code)]
    let name = unsafe { <T as ZeroCopySend>::type_name() };
    format!(
        "'{name}' (size {}, align {})",
        size_of::<T>(),
        align_of::<T>()
    )
}

/// The refusal for a publish-subscribe service `name` that could not be opened with payload
/// `T`, user header `H` and `qos` (iceoryx2's error `err`).
pub(crate) fn pubsub_open<T: ZeroCopySend, H: ZeroCopySend>(
    node: &Node<ipc::Service>,
    name: &ServiceName,
    qos: &PubSubQos,
    err: &str,
) -> ContractError {
    let existing =
        match ipc::Service::details(name, node.config(), MessagingPattern::PublishSubscribe) {
            Ok(Some(d)) => d.static_details,
            _ => {
                return ContractError::Transport(format!(
                    "cannot open service {name} ({err}); the contract (wire version \
                     {WIRE_VERSION}) requires {} (docs/wire.md, Services)",
                    qos.describe()
                ))
            }
        };
    let ps = existing.publish_subscribe();
    let types = ps.message_type_details();
    let (want_payload, want_header) = (type_of_rust::<T>(), type_of_rust::<H>());
    let (have_payload, have_header) = (type_of(&types.payload), type_of(&types.user_header));
    if (&have_payload, &have_header) != (&want_payload, &want_header) {
        return ContractError::Refused(format!(
            "service {name} carries payload {have_payload} with user header {have_header}, \
             but wire version {WIRE_VERSION} needs payload {want_payload} with user header \
             {want_header} ({err}): see docs/wire.md for the layouts; a Rust peer built from \
             another source must be rebuilt, or use another --prefix"
        ));
    }
    let have = PubSubQos {
        max_publishers: ps.max_publishers(),
        max_subscribers: ps.max_subscribers(),
        subscriber_max_buffer_size: ps.subscriber_max_buffer_size(),
        history_size: ps.history_size(),
        safe_overflow: ps.has_safe_overflow(),
    };
    let enough = have.max_publishers >= qos.max_publishers
        && have.max_subscribers >= qos.max_subscribers
        && have.subscriber_max_buffer_size >= qos.subscriber_max_buffer_size
        && have.history_size >= qos.history_size
        && have.safe_overflow == qos.safe_overflow;
    if enough {
        return ContractError::Transport(format!("cannot open service {name}: {err}"));
    }
    ContractError::Refused(format!(
        "service {name} was created with max_publishers {}, max_subscribers {}, \
         subscriber_max_buffer_size {}, history_size {}, safe overflow {} ({err}), but wire \
         version {WIRE_VERSION} requires {}: create it with these (docs/wire.md, Services) or \
         use another --prefix",
        have.max_publishers,
        have.max_subscribers,
        have.subscriber_max_buffer_size,
        have.history_size,
        if have.safe_overflow { "on" } else { "off" },
        qos.describe()
    ))
}

/// An event or blackboard service `name` that could not be opened.
pub(crate) fn other_open(name: &ServiceName, pattern: &str, err: &str) -> ContractError {
    if err.contains("Incompatible") || err.contains("DoesNotSupport") {
        ContractError::Refused(format!(
            "{pattern} service {name} exists with settings outside the contract (wire version \
             {WIRE_VERSION}): {err}; see docs/wire.md, Services, or use another --prefix"
        ))
    } else {
        ContractError::Transport(format!("cannot open {pattern} service {name}: {err}"))
    }
}
