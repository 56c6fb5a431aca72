//! Every payload's layout as the compiler lays it out: field offsets, sizes and alignments
//! from `core::mem::offset_of!`/`size_of`/`align_of`. `docs/wire.md`, the C header and the
//! Python structures are checked against these tables (`tests/layout.rs`), so none of them
//! can drift from the Rust types.

use crate::{Estimate, Slot, StreamHeader, Truth};
use core::mem::{align_of, offset_of, size_of};
use iceoryx2::prelude::ZeroCopySend;

/// One field of a payload.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// Field name (as in Rust, C and Python).
    pub name: &'static str,
    /// Its type in Rust notation (`u32`, `[f64; 4]`).
    pub ty: &'static str,
    /// Offset from the start of the payload, in bytes.
    pub offset: usize,
    /// Size in bytes.
    pub size: usize,
    /// Alignment in bytes.
    pub align: usize,
}

/// One payload type.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TypeLayout {
    /// Rust (and C, Python) name: `Slot`, `StreamHeader`, ….
    pub name: &'static str,
    /// The iceoryx2 type name both sides must use.
    pub type_name: &'static str,
    /// `size_of`.
    pub size: usize,
    /// `align_of`.
    pub align: usize,
    /// Every field, in declaration (and memory) order.
    pub fields: Vec<Field>,
}

fn size_of_field<T, F>(_: fn(&T) -> &F) -> (usize, usize) {
    (size_of::<F>(), align_of::<F>())
}

macro_rules! fields {
    ($t:ty: $($f:ident: $ty:literal),* $(,)?) => {
        vec![$({
            let (size, align) = size_of_field(|s: &$t| &s.$f);
            Field { name: stringify!($f), ty: $ty, offset: offset_of!($t, $f), size, align }
        }),*]
    };
}

fn layout<T: ZeroCopySend>(name: &'static str, fields: Vec<Field>) -> TypeLayout {
    TypeLayout {
        name,
        // SAFETY: `type_name` has no preconditions; it is unsafe only to discourage overrides.
        #[allow(unsafe_code)]
        type_name: unsafe { <T as ZeroCopySend>::type_name() },
        size: size_of::<T>(),
        align: align_of::<T>(),
        fields,
    }
}

/// The layouts of [`Slot`], [`StreamHeader`], [`Estimate`] and [`Truth`], in that order.
pub fn layouts() -> Vec<TypeLayout> {
    vec![
        layout::<Slot>(
            "Slot",
            fields!(Slot:
                version: "u32", kind: "u32", stream_id: "u64", seq: "u64", k: "u32",
                node: "u8", nodes: "u8", ny: "u8", delivered: "u8", flags: "u32",
                tokens: "u32", send_ns: "u64", period_ns: "u64", stream_start_ns: "u64",
                y: "[f64; 4]",
            ),
        ),
        layout::<StreamHeader>(
            "StreamHeader",
            fields!(StreamHeader:
                version: "u32", nodes: "u8", nx: "u8", reserved: "u16", ny: "[u8; 8]",
                model: "u64", scenario: "[u8; 32]",
            ),
        ),
        layout::<Estimate>(
            "Estimate",
            fields!(Estimate:
                version: "u32", k: "u32", stream_id: "u64", seq: "u64", estimator: "u32",
                nx: "u32", name: "[u8; 16]", status: "u32", cov_kind: "u32", x: "[f64; 8]",
                p: "[f64; 36]", slot_send_ns: "u64", receive_ns: "u64", step_done_ns: "u64",
                late_folded: "u32", revised_from: "u32",
            ),
        ),
        layout::<Truth>(
            "Truth",
            fields!(Truth:
                version: "u32", k: "u32", stream_id: "u64", nx: "u32", reserved: "u32",
                x: "[f64; 8]",
            ),
        ),
    ]
}

/// Size and alignment of a Rust type written as in [`Field::ty`]: `u8`…`u64`, `f64`, and
/// arrays `[T; N]` of them.
pub fn size_align_of(ty: &str) -> Option<(usize, usize)> {
    let scalar = |t: &str| match t {
        "u8" => Some(1),
        "u16" => Some(2),
        "u32" => Some(4),
        "u64" | "f64" => Some(8),
        _ => None,
    };
    if let Some(inner) = ty.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
        let (t, n) = inner.split_once(';')?;
        let s = scalar(t.trim())?;
        return Some((s * n.trim().parse::<usize>().ok()?, s));
    }
    scalar(ty).map(|s| (s, s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_cover_every_byte_in_order_and_match_their_declared_types() {
        for t in layouts() {
            let mut end = 0;
            for f in &t.fields {
                assert_eq!(
                    size_align_of(f.ty),
                    Some((f.size, f.align)),
                    "{}.{}",
                    t.name,
                    f.name
                );
                // No implicit padding: every gap is an explicit reserved field.
                assert_eq!(
                    f.offset, end,
                    "{}.{} follows a padding hole",
                    t.name, f.name
                );
                end = f.offset + f.size;
            }
            assert_eq!(end, t.size, "{} ends in padding", t.name);
        }
    }
}
