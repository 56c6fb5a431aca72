use super::*;
use estpipe_wire::{SLOT_END, WIRE_VERSION};

fn header(nodes: u8, ny: &[usize]) -> StreamHeader {
    StreamHeader::new("t", usize::from(nodes), 2, ny, 0x55)
}

fn slot(k: u32, node: u8, nodes: u8, sid: u64) -> Slot {
    let mut y = [0.0; MAX_NY];
    y[0] = f64::from(k) + f64::from(node) / 10.0;
    let o = Observation {
        k,
        node,
        delivered: node != 1,
        ny: 1,
        y: if node != 1 { y } else { [0.0; MAX_NY] },
        flags: 0,
        tokens: None,
    };
    estpipe_wire::observation::slot_of(&o, nodes, sid, 10, 0, 100)
}

type Out = Vec<(u32, Vec<Observation>)>;

fn run(a: &mut Assembler, h: &StreamHeader, slots: &[Slot]) -> (Out, Vec<Pushed>) {
    let mut out = Vec::new();
    let mut pushed = Vec::new();
    for s in slots {
        pushed.push(a.push_slot(s, h, 1000));
        while let Some(i) = a.next_ready() {
            out.push((i.k, i.obs.to_vec()));
        }
    }
    (out, pushed)
}

fn ks(out: &Out) -> Vec<u32> {
    out.iter().map(|o| o.0).collect()
}

#[test]
fn complete_stream_in_any_node_order_yields_every_instant_once() {
    let h = header(3, &[1, 1, 1]);
    let ordered: Vec<Slot> = (1..=4)
        .flat_map(|k| (0..3).map(move |n| slot(k, n, 3, 7)))
        .collect();
    // Per instant reversed node order, and node 2 one instant ahead of the others.
    let mut shuffled: Vec<Slot> = (1..=4)
        .flat_map(|k| (0..3).rev().map(move |n| slot(k, n, 3, 7)))
        .collect();
    shuffled.swap(3, 2);
    let mut a = Assembler::new(&h, Limits::default());
    let (o1, _) = run(&mut a, &h, &ordered);
    let mut b = Assembler::new(&h, Limits::default());
    let (o2, _) = run(&mut b, &h, &shuffled);
    assert_eq!(ks(&o1), [1, 2, 3, 4]);
    assert_eq!(o1, o2);
    assert!(o1.iter().all(|(k, o)| o.len() == 3
        && o.iter()
            .enumerate()
            .all(|(n, x)| x.k == *k && usize::from(x.node) == n)));
    assert_eq!(a.counts.received, 12);
    assert_eq!(a.counts.delivered, 8);
    assert_eq!(a.counts.dropped_by_channel, 4);
    assert_eq!(a.counts.lost_in_ipc, 0);
    assert_eq!(a.counts, b.counts);
}

#[test]
fn per_node_ny_comes_from_the_header() {
    let h = header(2, &[1, 3]);
    let mut a = Assembler::new(&h, Limits::default());
    let mut s1 = slot(1, 1, 2, 1);
    s1.delivered = 1;
    s1.ny = 3;
    s1.y[..3].copy_from_slice(&[1.0, 2.0, 3.0]);
    let (out, p) = run(&mut a, &h, &[slot(1, 0, 2, 1), s1]);
    assert_eq!(p, [Pushed::Data, Pushed::Data]);
    assert_eq!(out[0].1[0].ny, 1);
    assert_eq!(out[0].1[1].ny, 3);
    assert_eq!(out[0].1[1].measurement(), Some(&[1.0, 2.0, 3.0][..]));
    // ny 1 on node 1 is not what the header announced.
    let mut bad = slot(2, 1, 2, 1);
    bad.delivered = 1;
    bad.ny = 1;
    let (_, p) = run(&mut a, &h, &[bad]);
    assert_eq!(p, [Pushed::Refused(SlotFault::Ny)]);
    assert_eq!(a.counts.skipped.ny, 1);
}

#[test]
fn gaps_become_counted_ipc_losses_at_the_right_instant_and_node() {
    let h = header(2, &[1, 1]);
    let mut a = Assembler::new(&h, Limits::default());
    // Lose (2,1), (3,0), (3,1), (4,0).
    let slots = [
        slot(1, 0, 2, 1),
        slot(1, 1, 2, 1),
        slot(2, 0, 2, 1),
        slot(4, 1, 2, 1),
        slot(5, 0, 2, 1),
    ];
    let (out, _) = run(&mut a, &h, &slots);
    // Instant 4 needs node 0's slot 4, known lost only when its slot 5 came.
    assert_eq!(ks(&out), [1, 2, 3, 4]);
    assert_eq!(a.counts.lost_in_ipc, 4);
    let lost = |k: usize, n: usize| {
        let o = &out[k - 1].1[n];
        !o.delivered && o.flags & FLAG_IPC_LOST != 0 && o.k == k as u32 && o.node == n as u8
    };
    assert!(lost(2, 1) && lost(3, 0) && lost(3, 1) && lost(4, 0));
    assert!(out[1].1[0].delivered && out[3].1[1].flags & FLAG_IPC_LOST == 0);
}

#[test]
fn a_gap_after_the_relay_changed_is_lost_on_the_network_once() {
    let h = header(2, &[1, 1]);
    let mut a = Assembler::new(&h, Limits::default());
    let (_, _) = run(&mut a, &h, &[slot(1, 0, 2, 1), slot(1, 1, 2, 1)]);
    // A bridge went away after instant 1 and another took over node 0's stream at 4;
    // node 1's stream came on through the same publisher and lost 2 in the IPC.
    a.relay_changed(0);
    let (out, _) = run(
        &mut a,
        &h,
        &[slot(4, 0, 2, 1), slot(3, 1, 2, 1), slot(6, 0, 2, 1)],
    );
    assert_eq!(ks(&out), [2, 3]);
    // Node 0: 2 and 3 on the network (the relay's gap), 5 in the IPC (a later gap).
    assert_eq!(a.counts.lost_on_network, 2);
    assert_eq!(a.counts.lost_in_ipc, 2);
    let o = &out[0].1[0];
    assert!(!o.delivered && o.flags == FLAG_IPC_LOST | FLAG_NET_LOST);
    assert_eq!(out[0].1[1].flags, FLAG_IPC_LOST);
    assert_eq!(a.counts.received, 5);
}

#[test]
fn a_measurement_flagged_lost_on_the_network_is_handed_on_as_lost() {
    // A foreign publisher setting FLAG_NET_LOST on a delivered slot: counted lost on the
    // network, so its measurement must not reach the estimators either.
    let h = header(1, &[1]);
    let mut a = Assembler::new(&h, Limits::default());
    let mut s2 = slot(2, 0, 1, 1);
    s2.flags |= FLAG_NET_LOST;
    assert_eq!(s2.delivered, 1);
    let (out, _) = run(&mut a, &h, &[slot(1, 0, 1, 1), s2, slot(3, 0, 1, 1)]);
    assert_eq!(ks(&out), [1, 2, 3]);
    let o = &out[1].1[0];
    assert!(!o.delivered && o.flags & FLAG_NET_LOST != 0, "{o:?}");
    assert!(o.y.iter().all(|v| *v == 0.0), "{o:?}");
    assert!(out[0].1[0].delivered);
    assert!(out[2].1[0].delivered);
    assert_eq!((a.counts.received, a.counts.lost_on_network), (2, 1));
}

#[test]
fn per_node_end_markers_fill_the_tail_and_end_the_stream() {
    let h = header(2, &[1, 1]);
    let mut a = Assembler::new(&h, Limits::default());
    let (out, p) = run(
        &mut a,
        &h,
        &[
            slot(1, 0, 2, 5),
            slot(1, 1, 2, 6),
            Slot::marker(SLOT_END, 3, 0, 2, 5, 0),
            Slot::marker(SLOT_END, 3, 1, 2, 6, 0),
        ],
    );
    assert_eq!(p, [Pushed::Data, Pushed::Data, Pushed::Marker, Pushed::End]);
    assert_eq!(ks(&out), [1, 2, 3]);
    assert_eq!(a.counts.lost_in_ipc, 4);
    assert_eq!(a.counts.markers, 2);
}

#[test]
fn an_abort_of_one_node_ends_its_stream_only() {
    let h = header(2, &[1, 1]);
    let mut a = Assembler::new(&h, Limits::default());
    let (out, p) = run(
        &mut a,
        &h,
        &[
            slot(1, 0, 2, 5),
            Slot::marker(SLOT_ABORT, 0, 1, 2, 6, 0),
            slot(2, 0, 2, 5),
            Slot::marker(SLOT_END, 2, 0, 2, 5, 0),
        ],
    );
    assert_eq!(
        p,
        [Pushed::Data, Pushed::Marker, Pushed::Data, Pushed::Abort]
    );
    assert_eq!(ks(&out), [1, 2]);
    assert_eq!(a.counts.lost_after_end, 2);
}

#[test]
fn joining_mid_stream_and_restarts() {
    let h = header(1, &[1]);
    let mut a = Assembler::new(&h, Limits::default());
    // Subscribed after the stream started (at 100): a join.
    a.set_subscribed_ns(200);
    let (out, _) = run(&mut a, &h, &[slot(3, 0, 1, 9), slot(4, 0, 1, 9)]);
    assert_eq!(ks(&out), [1, 2, 3, 4]);
    assert_eq!(a.counts.missed_before_join, 2);
    assert_eq!(a.counts.lost_in_ipc, 0);
    // Another stream id in the middle is no restart: counted, skipped.
    let (_, p) = run(&mut a, &h, &[slot(5, 0, 1, 10)]);
    assert_eq!(p, [Pushed::Ignored]);
    assert_eq!(a.counts.skipped.stream, 1);
    // A new stream id at k = 1 is.
    let restarted = slot(1, 0, 1, 10);
    let (_, p) = run(&mut a, &h, &[restarted]);
    assert_eq!(p, [Pushed::NewStream]);
    a.reset();
    let (out, p) = run(&mut a, &h, &[restarted, slot(5, 0, 1, 9), slot(1, 0, 1, 9)]);
    assert_eq!(p, [Pushed::Data, Pushed::Ignored, Pushed::Ignored]);
    assert_eq!(ks(&out), [1]);
    assert_eq!(a.counts.skipped.stale_stream, 2);
}

#[test]
fn losses_before_the_first_slot_of_a_stream_we_saw_start_are_ipc_losses() {
    let h = header(1, &[1]);
    let mut a = Assembler::new(&h, Limits::default());
    a.set_subscribed_ns(50); // before the stream started at 100
    let (out, _) = run(&mut a, &h, &[slot(3, 0, 1, 9)]);
    assert_eq!(out.len(), 3);
    assert_eq!(a.counts.lost_in_ipc, 2);
    assert_eq!(a.counts.missed_before_join, 0);
}

#[test]
fn hostile_fields_are_counted_and_bounded() {
    let h = header(1, &[1]);
    let lim = Limits {
        max_gap: 10,
        instant_deadline_ns: 0,
        lag: 0,
    };
    let mut a = Assembler::new(&h, lim);
    let mut v = slot(2, 0, 1, 1);
    v.version = WIRE_VERSION + 1;
    let mut far = slot(1_000_000, 0, 1, 1);
    far.seq = 999_999;
    let mut max = slot(u32::MAX, 0, 1, 1);
    max.seq = u64::from(u32::MAX) - 1;
    let huge_end = Slot::marker(SLOT_END, u32::MAX, 0, 1, 1, 0);
    let mut abab = slot(2, 0, 1, 2);
    abab.k = 3;
    abab.seq = 2;
    let mut period = slot(2, 0, 1, 1);
    period.period_ns = 1 << 62;
    period.send_ns = 0;
    let mut other = h;
    other.model ^= 1;
    let (out, p) = run(
        &mut a,
        &h,
        &[slot(1, 0, 1, 1), v, far, max, huge_end, abab, period],
    );
    assert_eq!(
        p,
        [
            Pushed::Data,
            Pushed::Ignored,
            Pushed::Ignored,
            Pushed::Ignored,
            Pushed::Ignored,
            Pushed::Ignored,
            Pushed::Data
        ]
    );
    assert_eq!(ks(&out), [1, 2]);
    let s = a.counts.skipped;
    assert_eq!((s.version, s.gap, s.marker, s.stream), (1, 2, 1, 1));
    assert_eq!(a.counts.anomalies.period_ns, 1);
    assert_eq!(a.counts.anomalies.send_ns, 1);
    let mut out = 0;
    let p = a.push(&slot(3, 0, 1, 1), &other, 0, &mut |_, _: &[Observation]| {
        out += 1
    });
    assert_eq!((p, out, a.counts.skipped.header), (Pushed::Ignored, 0, 1));
    assert_eq!(a.counts.slots_seen(), 8);
}

#[test]
fn paced_instants_wait_for_their_deadline_then_go_without_the_missing_node() {
    let h = header(2, &[1, 1]);
    let lim = Limits {
        max_gap: 10,
        instant_deadline_ns: 500,
        lag: 0,
    };
    let mut a = Assembler::new(&h, lim);
    let mut s0 = slot(1, 0, 2, 1);
    s0.period_ns = 1000;
    let mut out = Vec::new();
    let mut emit = |k, o: &[Observation]| out.push((k, o.to_vec()));
    assert_eq!(a.push(&s0, &h, 1000, &mut emit), Pushed::Data);
    assert_eq!(a.next_expiry(), Some(1500));
    a.expire(1499, &mut emit);
    a.expire(1500, &mut emit);
    // Node 1's slot 1 comes late.
    let mut s1 = slot(1, 1, 2, 1);
    s1.period_ns = 1000;
    assert_eq!(a.push(&s1, &h, 1600, &mut emit), Pushed::Ignored);
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].1[1].flags, FLAG_IPC_LOST);
    assert_eq!((a.counts.lost_deadline, a.counts.late), (1, 1));
}

#[test]
fn blocking_streams_never_lose_by_deadline_but_overrun_the_window() {
    let h = header(2, &[1, 1]);
    let mut a = Assembler::new(&h, Limits::default());
    let mut n = 0u32;
    let mut emit = |_k, _o: &[Observation]| n += 1;
    for k in 1..=WINDOW as u32 + 2 {
        a.push(&slot(k, 0, 2, 1), &h, 0, &mut emit);
    }
    a.expire(u64::MAX, &mut emit);
    assert_eq!(n, 2);
    assert_eq!(a.counts.lost_overrun, 2);
    assert_eq!(a.counts.lost_deadline, 0);
}

#[test]
fn an_instant_carries_the_times_of_the_slot_pushed_last() {
    let h = header(2, &[1, 1]);
    let lim = Limits {
        max_gap: 10,
        instant_deadline_ns: 500,
        lag: 0,
    };
    let mut a = Assembler::new(&h, lim);
    let mut s0 = slot(1, 0, 2, 7);
    s0.period_ns = 1000;
    s0.send_ns = 900;
    assert_eq!(a.push_slot(&s0, &h, 1000), Pushed::Data);
    assert!(a.next_ready().is_none());
    // Node 1's slot completes instant 1: the instant carries its times.
    let mut s1 = slot(1, 1, 2, 8);
    s1.period_ns = 1000;
    s1.send_ns = 1100;
    assert_eq!(a.push_slot(&s1, &h, 1200), Pushed::Data);
    let i = a.next_ready().unwrap();
    let times = SlotTimes {
        send_ns: 1100,
        recv_ns: 1200,
        stream_id: 7,
    };
    assert_eq!((i.k, i.obs.len(), i.slot), (1, 2, times));
    assert!(a.next_ready().is_none());
    // Instant 2 given up by its deadline: the last slot's times; a send time after the
    // receipt is none.
    let mut s2 = slot(2, 0, 2, 7);
    s2.period_ns = 1000;
    s2.send_ns = 5000;
    assert_eq!(a.push_slot(&s2, &h, 2000), Pushed::Data);
    assert!(a.next_ready().is_none());
    a.expire_due(2500);
    let i = a.next_ready().unwrap();
    assert_eq!(i.k, 2);
    assert_eq!(i.slot.send_ns, 0);
    assert_eq!(i.slot.recv_ns, 2000);
    assert!(a.next_ready().is_none());
}

#[test]
fn a_jump_past_the_window_hands_on_every_instant_in_order_before_it_is_placed() {
    // One node far ahead: the window's oldest instants are handed on first, then the slot
    // takes the place of one of them in the ring.
    let h = header(2, &[1, 1]);
    let lim = Limits {
        max_gap: 2 * WINDOW as u32,
        instant_deadline_ns: 0,
        lag: 0,
    };
    let mut a = Assembler::new(&h, lim);
    let (out, _) = run(
        &mut a,
        &h,
        &[slot(1, 0, 2, 1), slot(1, 1, 2, 1), slot(2, 1, 2, 1)],
    );
    assert_eq!(ks(&out), [1]);
    let far = WINDOW as u32 + 5;
    let (out, p) = run(&mut a, &h, &[slot(far, 1, 2, 1)]);
    assert_eq!(p, [Pushed::Data]);
    assert_eq!(ks(&out), (2..=5).collect::<Vec<_>>());
    // Instant 2 kept node 1's slot; node 0's was overrun.
    assert_eq!(out[0].1[1].flags, 0);
    assert_eq!(out[0].1[0].flags, FLAG_IPC_LOST);
    let (out, _) = run(&mut a, &h, &[slot(far, 0, 2, 1)]);
    assert_eq!(out.len(), WINDOW);
    assert_eq!(out.last().unwrap().0, far);
    assert_eq!(out.last().unwrap().1[1].k, far);
    assert_eq!(a.counts.instants, u64::from(far));
}
