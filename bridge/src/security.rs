//! What the bridge checks in the security sections of a `--zenoh-config` before it opens
//! anything (docs/security.md, "The zenoh link"): one line, exit 2, for a configuration
//! this build would not honour or that would leave the link open.
//!
//! * A section the build cannot honour: zenoh accepts `transport/auth/usrpwd` without its
//!   `auth_usrpwd` feature and `transport/link/tls` without its TLS transport, and then runs
//!   unauthenticated, or in clear text, without a word.
//! * Mutual TLS with an endpoint that is not TLS: the certificates guard only `tls/` (and
//!   `quic/`) links, so a `tcp/` or `udp/` listener — zenoh's default for a peer is
//!   `tcp/[::]:0`, every interface — lets a peer without a certificate in, and a `tcp/`
//!   connect carries the stream in clear text.
//! * A file the TLS or user/password section names that cannot be read: zenoh would find it
//!   only when the session opens, in an error that reads like a failure of the network.

use anyhow::{bail, Result};

/// The security features this build of zenoh has.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Built {
    /// zenoh's `auth_usrpwd` (the bridge's feature `auth`).
    pub auth: bool,
    /// zenoh's TLS and QUIC transports (the bridge's feature `tls`).
    pub tls: bool,
}

impl Built {
    /// This build's.
    pub(crate) const THIS: Self = Self {
        auth: cfg!(feature = "auth"),
        tls: cfg!(feature = "tls"),
    };
}

const USRPWD: [&str; 2] = [
    "transport/auth/usrpwd/user",
    "transport/auth/usrpwd/dictionary_file",
];

const TLS: [&str; 6] = [
    "transport/link/tls/root_ca_certificate",
    "transport/link/tls/listen_private_key",
    "transport/link/tls/listen_certificate",
    "transport/link/tls/connect_private_key",
    "transport/link/tls/connect_certificate",
    "transport/link/tls/enable_mtls",
];

/// Files a section names (the TLS ones without `enable_mtls`, the user/password dictionary).
const FILES: [&str; 6] = [
    "transport/link/tls/root_ca_certificate",
    "transport/link/tls/listen_private_key",
    "transport/link/tls/listen_certificate",
    "transport/link/tls/connect_private_key",
    "transport/link/tls/connect_certificate",
    "transport/auth/usrpwd/dictionary_file",
];

/// Every check of this module on the configuration as it will be opened (the file with
/// `--listen`/`--connect` applied).
pub(crate) fn check(c: &zenoh::Config, built: Built) -> Result<()> {
    refuse_unbuilt(c, built)?;
    for key in FILES {
        if let Some(path) = string_at(c, key) {
            if let Err(e) = std::fs::File::open(&path) {
                bail!("--zenoh-config {key}: cannot read {path}: {e}");
            }
        }
    }
    if string_at(c, "transport/link/tls/enable_mtls").as_deref() == Some("true") {
        let mode = string_at(c, "mode").unwrap_or_else(|| "peer".into());
        for (what, key) in [
            ("listen on", "listen/endpoints"),
            ("connect to", "connect/endpoints"),
        ] {
            let (list, per_mode) = endpoints(c, key, &mode);
            for e in list {
                if !(e.starts_with("tls/") || e.starts_with("quic/")) {
                    bail!(
                        "--zenoh-config enables mutual TLS, but this side would also {what} {e}, \
                         which no certificate guards{}: give only tls/ endpoints (listen \
                         endpoints [] on the side that connects; docs/security.md, \"The zenoh \
                         link\")",
                        if per_mode {
                            " (zenoh's default for a peer where listen.endpoints is not set)"
                        } else {
                            ""
                        }
                    );
                }
            }
        }
    }
    Ok(())
}

/// A section this build would ignore: refused in one line that says which feature it needs
/// (issue #39).
fn refuse_unbuilt(c: &zenoh::Config, built: Built) -> Result<()> {
    if USRPWD.iter().any(|k| is_set(c, k)) && !built.auth {
        bail!(
            "--zenoh-config sets transport/auth/usrpwd, but this build has no zenoh user/password \
             authentication and would run unauthenticated: build with `--features auth` \
             (docs/security.md, \"The zenoh link\")"
        );
    }
    if TLS.iter().any(|k| is_set(c, k)) && !built.tls {
        bail!(
            "--zenoh-config sets transport/link/tls, but this build has no zenoh TLS transport \
             and would ignore it: build with `--features tls` (docs/security.md, \"The zenoh \
             link\")"
        );
    }
    Ok(())
}

fn is_set(c: &zenoh::Config, key: &str) -> bool {
    c.get_json(key)
        .is_ok_and(|v| !matches!(v.trim(), "null" | "{}" | "[]" | "\"\""))
}

/// A scalar of the configuration as text (a string without its quotes), if set.
fn string_at(c: &zenoh::Config, key: &str) -> Option<String> {
    let v: serde_json::Value = serde_json::from_str(&c.get_json(key).ok()?).ok()?;
    match v {
        serde_json::Value::Null => None,
        serde_json::Value::String(s) if s.is_empty() => None,
        serde_json::Value::String(s) => Some(s),
        other => Some(other.to_string()),
    }
}

/// The endpoints `key` gives in `mode`, and whether they come from a list per mode
/// (`{peer: [...]}`, the form of zenoh's own default when the key is not set).
fn endpoints(c: &zenoh::Config, key: &str, mode: &str) -> (Vec<String>, bool) {
    let Some(v) = c
        .get_json(key)
        .ok()
        .and_then(|j| serde_json::from_str::<serde_json::Value>(&j).ok())
    else {
        return (Vec::new(), false);
    };
    let (list, per_mode) = match &v {
        serde_json::Value::Object(m) => (m.get(mode).cloned().unwrap_or_default(), true),
        other => (other.clone(), false),
    };
    let list = list
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|e| e.as_str().map(str::to_owned))
                .collect()
        })
        .unwrap_or_default();
    (list, per_mode)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(json5: &str) -> zenoh::Config {
        zenoh::Config::from_json5(json5).unwrap()
    }

    const NONE: Built = Built {
        auth: false,
        tls: false,
    };
    const ALL: Built = Built {
        auth: true,
        tls: true,
    };

    #[test]
    fn a_section_the_build_cannot_honour_is_refused_with_the_feature_to_build() {
        let usrpwd = config(r#"{ transport: { auth: { usrpwd: { user: "u", password: "p" } } } }"#);
        let e = check(&usrpwd, NONE).unwrap_err().to_string();
        assert!(e.contains("--features auth"), "{e}");
        assert!(check(&usrpwd, ALL).is_ok());
        let tls = config(r#"{ transport: { link: { tls: { enable_mtls: false } } } }"#);
        let e = check(&tls, NONE).unwrap_err().to_string();
        assert!(e.contains("--features tls"), "{e}");
        assert!(check(&config("{}"), NONE).is_ok());
    }

    #[test]
    fn mutual_tls_with_a_clear_text_endpoint_is_refused() {
        let mtls = r#"transport: { link: { tls: { enable_mtls: true } } }"#;
        // zenoh's default listener of a peer, tcp/[::]:0.
        let e = check(&config(&format!("{{ {mtls} }}")), ALL)
            .unwrap_err()
            .to_string();
        assert!(e.contains("tcp/[::]:0") && e.contains("default"), "{e}");
        let e = check(
            &config(&format!(
                r#"{{ {mtls}, listen: {{ endpoints: [] }}, connect: {{ endpoints: ["tcp/127.0.0.1:7447"] }} }}"#
            )),
            ALL,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("connect to tcp/127.0.0.1:7447"), "{e}");
        let ok = config(&format!(
            r#"{{ {mtls}, listen: {{ endpoints: ["tls/127.0.0.1:7447"] }} }}"#
        ));
        assert!(check(&ok, ALL).is_ok());
    }

    #[test]
    fn an_unreadable_certificate_is_refused() {
        let c = config(
            r#"{ transport: { link: { tls: { root_ca_certificate: "/nonexistent/ca.pem" } } } }"#,
        );
        let e = check(&c, ALL).unwrap_err().to_string();
        assert!(
            e.contains("root_ca_certificate") && e.contains("/nonexistent/ca.pem"),
            "{e}"
        );
    }
}
