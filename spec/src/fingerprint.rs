//! The model fingerprint of a stream (docs/wire.md, "Model fingerprint"): FNV-1a 64 over
//! everything an [`EstimatorSpec`] holds that an estimator reads, so that a publisher and a
//! runner whose specs agree accept each other, and any difference an estimator could see is
//! refused.

use estpipe_wire::Fnv1a64;
use nalgebra::DMatrix;

use crate::channel::ChannelKnowledge;
use crate::{EstimatorSpec, Model};

/// The first thing a model fingerprint hashes: names the definition in docs/wire.md, changed
/// with it.
pub const FINGERPRINT_TAG: &str = "estpipe-model-2";

/// Feeds `m` to a fingerprint: rows, cols, then the entries column by column.
pub fn fingerprint_matrix(h: &mut Fnv1a64, m: &DMatrix<f64>) {
    h.matrix(m.nrows(), m.ncols(), m.as_slice());
}

/// The fingerprint of `spec` (its name, loss rate and gate are not part of it: they are the
/// runner's choices, not the model).
pub fn fingerprint(spec: &EstimatorSpec) -> u64 {
    let mut h = Fnv1a64::new();
    h.str(FINGERPRINT_TAG)
        .u64(spec.nodes() as u64)
        .u64(spec.nx() as u64);
    for m in 0..spec.nodes() {
        h.u64(spec.node_ny(m) as u64);
    }
    match &spec.model {
        Model::Linear(l) => {
            h.str("linear");
            fingerprint_matrix(&mut h, l.a());
            fingerprint_matrix(&mut h, l.b());
            fingerprint_matrix(&mut h, l.q());
            h.u64(l.sensors().len() as u64);
            for s in l.sensors() {
                fingerprint_matrix(&mut h, &s.c);
                fingerprint_matrix(&mut h, &s.d);
                fingerprint_matrix(&mut h, &s.r);
            }
            match l.control() {
                Some(c) => c.fingerprint(h.u64(1)),
                None => {
                    h.u64(0);
                }
            }
        }
        // The matrices and f are fixed code (the core's Seed003Example); only the noise is a
        // parameter.
        Model::Seed003 { w_var } => {
            h.str("seed003").f64(*w_var);
        }
    }
    h.matrix(spec.prior.mean.len(), 1, spec.prior.mean.as_slice());
    fingerprint_matrix(&mut h, &spec.prior.cov);
    channel(&mut h, &spec.channel);
    h.finish()
}

/// The channel knowledge: each part present, in a fixed order, by name then parameters.
fn channel(h: &mut Fnv1a64, c: &ChannelKnowledge) {
    if let Some(o) = &c.occlusion {
        h.str("occlusion")
            .u64(o.e().len() as u64)
            .f64s(o.e())
            .f64(o.psi())
            .u64(o.count() as u64);
        for (c, r) in o.centres().iter().zip(o.radii()) {
            h.f64(*c).f64(*r);
        }
    }
    if let Some(b) = &c.token_bucket {
        h.str("token-bucket")
            .u64(b.a.into())
            .u64(b.b.into())
            .u64(b.s.into())
            .u64(b.z0.into());
    }
    if let Some(t) = &c.tobit {
        h.str("tobit-censoring").u64(t.nodes() as u64);
        for m in 0..t.nodes() {
            h.u64(t.tau(m).len() as u64).f64s(t.tau(m));
        }
    }
    if let Some(t) = &c.event_trigger {
        h.str("event-trigger-token-bucket").u64(t.nodes() as u64);
        for m in 0..t.nodes() {
            let p = t.trigger(m);
            h.f64(p.sigma())
                .f64(p.chi())
                .f64(p.lambda())
                .f64(p.eta0())
                .u64(t.reference(m).len() as u64)
                .f64s(t.reference(m));
        }
        let (initial, rate, capacity) = t.bucket();
        h.u64(initial.into()).u64(rate.into()).u64(capacity.into());
        for &cost in t.costs() {
            h.u64(cost.into());
        }
        h.u64(t.allows_paper_violation().into());
    }
}
