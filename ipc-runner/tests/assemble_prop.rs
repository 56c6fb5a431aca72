//! Property tests of slot validation and assembly (`ipc_runner::run::assemble`, docs/wire.md
//! "What the runner does with a bad slot"): over 10⁶ random slots — interleaved valid
//! per-node streams in random order, with fields replaced by random and extreme values and
//! stray stream ids — nothing panics, and after every slot:
//!
//! * the slot is counted exactly once (`Counts::slots_seen` grows by one);
//! * the instants handed on are strictly increasing within a session (none twice), each with
//!   one observation per node in node order, of that instant, with the header's ny, and a
//!   finite measurement when delivered;
//! * the work is bounded: at most `2·max_gap + WINDOW + 1` instants per slot;
//! * `Counts::instants` equals the instants actually handed on.
//!
//! A second property: a clean stream of several nodes, shuffled within a bounded distance,
//! hands on every instant exactly once with exactly the observations that were sent.
//!
//! The slots of a case come from a small xorshift generator seeded by proptest (so a case
//! costs no proptest machinery per slot); 1000 cases × 1000 slots run in a few seconds in
//! release.

use channel_sim::Observation;
use estpipe_wire::{Slot, StreamHeader, FLAG_IPC_LOST, SLOT_ABORT, SLOT_END};
use ipc_runner::run::assemble::{Assembler, Limits, Pushed, WINDOW};
use proptest::prelude::*;

/// xorshift64*: the slots of one case.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
    fn chance(&mut self, p_percent: u64) -> bool {
        self.below(100) < p_percent
    }
    /// An extreme or random value of a field.
    fn wild(&mut self) -> u64 {
        match self.below(6) {
            0 => 0,
            1 => u64::MAX,
            2 => u64::from(u32::MAX),
            3 => self.below(8),
            4 => 1 << self.below(64),
            _ => self.next(),
        }
    }
    fn wild_f64(&mut self) -> f64 {
        match self.below(5) {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => f64::NEG_INFINITY,
            3 => f64::from_bits(self.next()),
            _ => self.below(1000) as f64 - 500.0,
        }
    }
}

/// A valid data slot of `node` at instant `k` of stream `sid`.
fn valid(h: &StreamHeader, node: u8, k: u32, sid: u64, period: u64, rng: &mut Rng) -> Slot {
    let mut s = Slot::data(k, node, h.nodes, sid);
    s.delivered = u8::from(rng.chance(70));
    s.ny = h.ny[usize::from(node)];
    if s.delivered == 1 {
        for y in s.y.iter_mut().take(usize::from(s.ny)) {
            *y = rng.below(1000) as f64 / 7.0;
        }
    } else if rng.chance(50) {
        s.ny = 0;
    }
    s.send_ns = 1 + rng.below(1000);
    s.period_ns = period;
    s.stream_start_ns = 10;
    s
}

/// Replaces one field of `s` by a random or extreme value.
fn corrupt(s: &mut Slot, rng: &mut Rng) {
    match rng.below(14) {
        0 => s.version = rng.wild() as u32,
        1 => s.kind = rng.wild() as u32,
        2 => s.stream_id = rng.wild(),
        3 => s.seq = rng.wild(),
        4 => {
            s.k = rng.wild() as u32;
            if rng.chance(50) {
                s.seq = u64::from(s.k).saturating_sub(1);
            }
        }
        5 => s.node = rng.wild() as u8,
        6 => s.nodes = rng.wild() as u8,
        7 => s.ny = rng.wild() as u8,
        8 => s.delivered = rng.wild() as u8,
        9 => s.send_ns = rng.wild(),
        10 => s.period_ns = rng.wild(),
        11 => s.stream_start_ns = rng.wild(),
        12 => {
            let i = rng.below(4) as usize;
            s.y[i] = rng.wild_f64();
        }
        _ => {
            // An END/ABORT with random bounds.
            s.kind = if rng.chance(50) { SLOT_END } else { SLOT_ABORT };
            s.k = rng.wild() as u32;
            s.seq = if rng.chance(50) {
                u64::from(s.k)
            } else {
                rng.wild()
            };
        }
    }
}

/// The instants one push handed on, checked as they come.
struct Check<'a> {
    h: &'a StreamHeader,
    last_k: u64,
    emitted: u64,
    in_push: u64,
}

impl Check<'_> {
    fn on(&mut self, k: u32, obs: &[Observation]) {
        let k = u64::from(k);
        assert!(k > self.last_k, "instant {k} after {}", self.last_k);
        assert!(k >= 1);
        self.last_k = k;
        self.emitted += 1;
        self.in_push += 1;
        assert_eq!(obs.len(), usize::from(self.h.nodes));
        for (n, o) in obs.iter().enumerate() {
            assert_eq!(usize::from(o.node), n);
            assert_eq!(u64::from(o.k), k);
            assert_eq!(o.ny, self.h.ny[n]);
            if let Some(m) = o.measurement() {
                assert!(m.iter().all(|v| v.is_finite()), "{o:?}");
            }
        }
    }
}

fn header(nodes: u8, rng: &mut Rng) -> StreamHeader {
    let ny: Vec<usize> = (0..nodes).map(|_| 1 + rng.below(4) as usize).collect();
    StreamHeader::new("prop", usize::from(nodes), 3, &ny, 0xfeed)
}

/// One case: `slots` slots of up to two interleaved stream generations on `nodes` nodes.
fn hostile_case(seed: u64, nodes: u8, max_gap: u32, paced: bool, slots: usize) {
    let mut rng = Rng(seed | 1);
    let h = header(nodes, &mut rng);
    let limits = Limits {
        max_gap,
        instant_deadline_ns: if paced { 50 } else { 0 },
        lag: (seed % 4) as u32,
    };
    let period = if paced { 10 } else { 0 };
    let mut a = Assembler::new(&h, limits);
    a.set_subscribed_ns(5);
    let mut other = h;
    other.model ^= 1;
    // Per node, the next instant of the current valid stream.
    let mut next_k = vec![1u32; usize::from(nodes)];
    let mut sid = 1u64;
    let mut check = Check {
        h: &h,
        last_k: 0,
        emitted: 0,
        in_push: 0,
    };
    let bound = 2 * u64::from(max_gap) + WINDOW as u64 + 1;
    let mut now = 100u64;
    for _ in 0..slots {
        now += rng.below(20);
        let node = rng.below(u64::from(nodes)) as u8;
        let m = usize::from(node);
        let mut s = if rng.chance(2) {
            // A legitimate restart of every node.
            sid += 1;
            next_k.iter_mut().for_each(|k| *k = 1);
            valid(&h, node, 1, sid, period, &mut rng)
        } else {
            valid(&h, node, next_k[m], sid, period, &mut rng)
        };
        // Valid streams advance, sometimes with a gap (lost slots).
        next_k[m] = next_k[m].saturating_add(1 + u32::from(rng.chance(5)) * rng.below(4) as u32);
        if rng.chance(25) {
            corrupt(&mut s, &mut rng);
        }
        let hdr = if rng.chance(1) { &other } else { &h };
        let before = a.counts.slots_seen();
        check.in_push = 0;
        let mut p = a.push(&s, hdr, now, &mut |k, o: &[Observation]| check.on(k, o));
        if p == Pushed::NewStream {
            assert_eq!(a.counts.slots_seen(), before, "a restart is not consumed");
            a.reset();
            check.last_k = 0; // a new session starts again at k = 1
            p = a.push(&s, hdr, now, &mut |k, o: &[Observation]| check.on(k, o));
            assert_ne!(
                p,
                Pushed::NewStream,
                "a reset stream accepts its first slot"
            );
        }
        assert_eq!(a.counts.slots_seen(), before + 1, "{s:?} → {p:?}");
        let mut late = [Observation::dropped(0, 0, 0, 0); estpipe_wire::MAX_NODES];
        match a.take_late(&mut late) {
            // A late slot: of an instant already handed on, within the lag, the others lost.
            Some((k, n)) => {
                assert_eq!(p, Pushed::Late);
                let lateness = a.next_instant() - u64::from(k);
                assert!(lateness >= 1 && lateness <= seed % 4, "{lateness}");
                assert_eq!(n, usize::from(nodes));
                let known = late[..n].iter().filter(|o| o.flags & FLAG_IPC_LOST == 0);
                assert_eq!(known.count(), 1);
            }
            None => assert_ne!(p, Pushed::Late),
        }
        if rng.chance(10) {
            a.expire(now, &mut |k, o: &[Observation]| check.on(k, o));
        }
        assert!(
            check.in_push <= bound,
            "{} instants for one slot",
            check.in_push
        );
        assert_eq!(a.counts.instants, check.emitted);
        if matches!(p, Pushed::End | Pushed::Abort) {
            // Every stream ended: a fresh session may follow (as a restart would).
            sid += 1;
            next_k.iter_mut().for_each(|k| *k = 1);
        }
    }
    assert!(a.counts.received <= slots as u64);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, failure_persistence: None, ..ProptestConfig::default() })]

    /// 1000 cases × 1000 slots: 10⁶ slots.
    #[test]
    fn hostile_slots_are_counted_once_and_never_break_the_invariants(
        seed in any::<u64>(),
        nodes in 1u8..=4,
        max_gap in prop_oneof![Just(1u32), 1u32..64, Just(1000)],
        paced in any::<bool>(),
    ) {
        hostile_case(seed, nodes, max_gap, paced, 1000);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, failure_persistence: None, ..ProptestConfig::default() })]

    /// A clean stream, shuffled within a distance: exactly what was sent, every instant once.
    #[test]
    fn a_shuffled_clean_stream_is_reassembled_exactly(
        seed in any::<u64>(),
        nodes in 1u8..=8,
        steps in 1u32..200,
        spread in 0usize..64,
    ) {
        let mut rng = Rng(seed | 1);
        let h = header(nodes, &mut rng);
        let want: Vec<Slot> = (1..=steps)
            .flat_map(|k| (0..nodes).map(move |n| (k, n)))
            .map(|(k, n)| valid(&h, n, k, 9, 0, &mut rng))
            .collect();
        // Any interleaving of the nodes' streams (each node's own slots stay in order, as
        // one publisher's queue keeps them), nodes up to `spread` instants apart.
        let mut next = vec![0u32; usize::from(nodes)];
        let mut sent = Vec::new();
        while sent.len() < want.len() {
            let n = rng.below(u64::from(nodes)) as usize;
            let slowest = *next.iter().min().unwrap();
            if next[n] < steps && next[n] <= slowest + spread as u32 {
                sent.push(want[next[n] as usize * usize::from(nodes) + n]);
                next[n] += 1;
            }
        }
        for n in 0..nodes {
            sent.push(Slot { stream_start_ns: 10, ..Slot::marker(SLOT_END, steps, n, nodes, 9, 1) });
        }
        let mut a = Assembler::new(&h, Limits::default());
        let mut got: Vec<(u32, Vec<Observation>)> = Vec::new();
        let mut last = Pushed::Ignored;
        for s in &sent {
            last = a.push(s, &h, 1000, &mut |k, o: &[Observation]| got.push((k, o.to_vec())));
        }
        prop_assert_eq!(last, Pushed::End);
        prop_assert_eq!(got.len(), steps as usize);
        for (i, (k, obs)) in got.iter().enumerate() {
            prop_assert_eq!(*k, i as u32 + 1);
            for o in obs {
                let w = &want[(*k as usize - 1) * usize::from(nodes) + usize::from(o.node)];
                prop_assert_eq!(o.delivered, w.delivered == 1);
                prop_assert_eq!(o.measurement(), w.measurement());
            }
        }
        prop_assert_eq!(a.counts.received, u64::from(steps) * u64::from(nodes));
        prop_assert_eq!(a.counts.lost_in_ipc + a.counts.lost_overrun + a.counts.late, 0);
    }
}
