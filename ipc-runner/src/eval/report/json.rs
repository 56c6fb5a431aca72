//! How the result's fields are written in the JSON (the attributes of
//! [`super::EvalResult`] and its parts name these).

use serde::ser::{SerializeMap, Serializer};
use serde::Serialize;

use crate::estimators::role::Role;

pub(super) fn is_zero(v: &u64) -> bool {
    *v == 0
}

pub(super) fn is_zero_f64(v: &f64) -> bool {
    *v == 0.0
}

pub(super) fn is_zero_u32(v: &u32) -> bool {
    *v == 0
}

/// An option written as its `Display` string (the form its flag takes).
pub(super) fn display_opt<S: Serializer, D: std::fmt::Display>(
    v: &Option<D>,
    s: S,
) -> Result<S::Ok, S::Error> {
    match v {
        Some(d) => s.collect_str(d),
        None => s.serialize_none(),
    }
}

pub(super) fn ordered_map<S: Serializer, V: Serialize>(
    entries: &[(String, V)],
    s: S,
) -> Result<S::Ok, S::Error> {
    let mut map = s.serialize_map(Some(entries.len()))?;
    for (k, v) in entries {
        map.serialize_entry(k, v)?;
    }
    map.end()
}

/// A role as its word in the tables.
pub(super) fn role_str<S: Serializer>(role: &Role, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(role.as_str())
}
