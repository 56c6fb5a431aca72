//! The live view's tap as the loop calls it (docs/view.md, "Cost to the loop"): one
//! `ViewTap::instant` per instant after its estimates are published, with and without a view.
//! With a view the record is taken off the queue in the same kernel (`try_recv`, what the
//! view's reader does in its own thread), so that the queue never fills and every call takes
//! the path of a view that keeps up; the count is an upper bound of the loop's share.

use estpipe_wire::{Observation, MAX_NX};
use ipc_runner::view::{ViewTap, TAP_QUEUE};

/// One call of a kernel (always `Ok`: `icount` counts failed steps as an error).
pub type TapFn = Box<dyn FnMut() -> Result<u32, ()>>;

/// `view/tap-off` (no view: the empty tap) and `view/tap-on` (a view that keeps up), on an
/// instant of three nodes (one dropped) with a truth.
pub fn kernels() -> Vec<(String, TapFn)> {
    let mut obs = [
        Observation::dropped(1, 0, 2, 0),
        Observation::dropped(1, 1, 2, 0),
        Observation::dropped(1, 2, 2, 0),
    ];
    obs[0].delivered = true;
    obs[2].delivered = true;
    let truth = [1.0; MAX_NX];
    let off = ViewTap::default();
    let (tx, rx) = std::sync::mpsc::sync_channel(TAP_QUEUE);
    let on = ViewTap::new(tx);
    let (mut k_off, mut k_on) = (0u32, 0u32);
    vec![
        (
            "view/tap-off".to_string(),
            Box::new(move || {
                k_off = k_off.wrapping_add(1);
                off.instant(1, k_off, std::hint::black_box(&obs), Some(&truth));
                Ok(k_off)
            }) as TapFn,
        ),
        (
            "view/tap-on".to_string(),
            Box::new(move || {
                k_on = k_on.wrapping_add(1);
                on.instant(1, k_on, std::hint::black_box(&obs), Some(&truth));
                // The record taken, as the view's reader does; an empty queue would be a bug
                // of the tap, and shows as a different count.
                Ok(rx.try_recv().map_or(0, |_| k_on))
            }),
        ),
    ]
}
