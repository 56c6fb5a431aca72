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

#[cfg(test)]
mod tests {
    use nalgebra::{DMatrix, DVector};

    use crate::channel::{Occlusion, TobitCensoring};
    use crate::control::{Control, Schedule};
    use crate::{ChannelKnowledge, EstimatorSpec, LinearModel, Model, Prior, Sensor};

    /// Every number of a spec, as rows; built into a spec twice, independently: in code and
    /// through TOML.
    #[derive(Clone, Debug)]
    struct Numbers {
        a: Vec<Vec<f64>>,
        b: Vec<Vec<f64>>,
        q: Vec<Vec<f64>>,
        c: Vec<Vec<f64>>,
        d: Vec<Vec<f64>>,
        r: Vec<Vec<f64>>,
        mean: Vec<f64>,
        cov: Vec<Vec<f64>>,
        centres: Vec<f64>,
        tau: Vec<f64>,
        bu: Vec<Vec<f64>>,
        u: Vec<f64>,
    }

    fn numbers() -> Numbers {
        Numbers {
            a: vec![vec![0.95, 0.1], vec![-0.1, 0.95]],
            b: vec![vec![1.0, 0.5], vec![0.0, 1.0]],
            q: vec![vec![0.01, 0.002], vec![0.002, 0.04]],
            c: vec![vec![1.0, 0.25], vec![0.0, 1.0]],
            d: vec![vec![1.0, 0.0], vec![0.3, 1.0]],
            r: vec![vec![0.25, 0.0], vec![0.0, 0.5]],
            mean: vec![0.5, -1.0],
            cov: vec![vec![1.0, 0.1], vec![0.1, 2.0]],
            centres: vec![20.0, 40.0],
            tau: vec![0.5, -0.75],
            bu: vec![vec![0.0], vec![1.0]],
            u: vec![0.3],
        }
    }

    fn m(rows: &[Vec<f64>]) -> DMatrix<f64> {
        DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
    }

    fn in_code(n: &Numbers, name: &str) -> EstimatorSpec {
        let sensor = Sensor {
            c: m(&n.c),
            d: m(&n.d),
            r: m(&n.r),
        };
        let linear = LinearModel::new(m(&n.a), m(&n.b), m(&n.q), vec![sensor])
            .unwrap()
            .with_control(Control::new(m(&n.bu), Schedule::Constant(n.u.clone()), 2).unwrap())
            .unwrap();
        let channel = ChannelKnowledge {
            occlusion: Some(
                Occlusion::new(vec![1.0, 0.0], 0.1, n.centres.clone(), vec![5.0, 5.0], 2).unwrap(),
            ),
            tobit: Some(TobitCensoring::new(vec![n.tau.clone()]).unwrap()),
            ..ChannelKnowledge::default()
        };
        let prior = Prior {
            mean: DVector::from_vec(n.mean.clone()),
            cov: m(&n.cov),
        };
        EstimatorSpec::new(name, Model::Linear(linear), prior, channel).unwrap()
    }

    /// The TOML of `n` (`{:?}` prints an f64 that reads back bit for bit).
    fn toml(n: &Numbers, extra: &str) -> String {
        let rows = |r: &[Vec<f64>]| {
            let v: Vec<String> = r.iter().map(|r| format!("{r:?}")).collect();
            format!("[{}]", v.join(", "))
        };
        format!(
            "{extra}\n[model]\na = {}\nb = {}\nq = {}\n\
             [control]\nb = {}\nu = {{ kind = \"constant\", value = {:?} }}\n\
             [prior]\nmean = {:?}\ncov = {}\n\
             [[sensors]]\nc = {}\nd = {}\nr = {}\n\
             [occlusion]\ne = [1.0, 0.0]\npsi = 0.1\ncentres = {:?}\nradii = [5.0, 5.0]\n\
             [tobit]\nthresholds = [{:?}]\n",
            rows(&n.a),
            rows(&n.b),
            rows(&n.q),
            rows(&n.bu),
            n.u,
            n.mean,
            rows(&n.cov),
            rows(&n.c),
            rows(&n.d),
            rows(&n.r),
            n.centres,
            n.tau,
        )
    }

    fn from_toml(n: &Numbers, extra: &str) -> EstimatorSpec {
        crate::file::parse(&toml(n, extra), "fp.toml", "fp").unwrap_or_else(|e| panic!("{e}"))
    }

    /// Every single-number change: (what, changed numbers).
    fn one_changed(f: impl Fn(f64) -> f64) -> Vec<(&'static str, Numbers)> {
        let n = numbers();
        let mut out = Vec::new();
        let mut push = |what, g: &dyn Fn(&mut Numbers)| {
            let mut c = n.clone();
            g(&mut c);
            out.push((what, c));
        };
        push("A", &|c| c.a[1][0] = f(c.a[1][0]));
        push("B", &|c| c.b[0][1] = f(c.b[0][1]));
        push("Q", &|c| c.q[1][1] = f(c.q[1][1]));
        push("C", &|c| c.c[0][1] = f(c.c[0][1]));
        push("D", &|c| c.d[1][0] = f(c.d[1][0]));
        push("R", &|c| c.r[0][0] = f(c.r[0][0]));
        push("prior mean", &|c| c.mean[1] = f(c.mean[1]));
        push("prior cov", &|c| c.cov[0][0] = f(c.cov[0][0]));
        push("occlusion centre", &|c| c.centres[1] = f(c.centres[1]));
        push("tobit threshold", &|c| c.tau[1] = f(c.tau[1]));
        push("control B_u", &|c| c.bu[1][0] = f(c.bu[1][0]));
        push("control u", &|c| c.u[0] = f(c.u[0]));
        out
    }

    #[test]
    fn a_spec_from_toml_and_one_in_code_agree() {
        let n = numbers();
        let (code, file) = (in_code(&n, "fp"), from_toml(&n, ""));
        assert_eq!(code, file);
        assert_eq!(code.fingerprint(), file.fingerprint());
        assert_eq!(code.stream_header(), file.stream_header());
    }

    #[test]
    fn one_ulp_anywhere_changes_the_fingerprint() {
        let base = in_code(&numbers(), "fp").fingerprint();
        let mut seen = vec![base];
        for (what, changed) in one_changed(f64::next_up) {
            let code = in_code(&changed, "fp").fingerprint();
            assert_ne!(code, base, "{what}");
            // The same change through TOML gives the same (new) fingerprint.
            assert_eq!(from_toml(&changed, "").fingerprint(), code, "{what}");
            // And differs from every other single change.
            assert!(!seen.contains(&code), "{what} collides");
            seen.push(code);
        }
        for (what, changed) in one_changed(f64::next_down) {
            assert_ne!(in_code(&changed, "fp").fingerprint(), base, "{what} (down)");
        }
    }

    #[test]
    fn name_loss_rate_and_gate_are_not_part_of_it() {
        let n = numbers();
        let base = in_code(&n, "fp");
        let other = in_code(&n, "another name")
            .with_loss_rate(Some(0.2))
            .unwrap()
            .with_gate(Some(0.99))
            .unwrap();
        assert_eq!(other.fingerprint(), base.fingerprint());
        let file = from_toml(&n, "name = \"x\"\nloss_rate = 0.1\ngate = 0.9");
        assert_eq!((file.loss_rate, file.gate), (Some(0.1), Some(0.9)));
        assert_eq!(file.fingerprint(), base.fingerprint());
        // But the channel knowledge is: without the Tobit thresholds it differs.
        let mut no_tobit = base.clone();
        no_tobit.channel.tobit = None;
        assert_ne!(no_tobit.fingerprint(), base.fingerprint());
    }

    #[test]
    fn minus_zero_and_zero_differ() {
        let mut n = numbers();
        n.b[1][0] = 0.0;
        let plus = in_code(&n, "fp").fingerprint();
        n.b[1][0] = -0.0;
        let minus = in_code(&n, "fp");
        assert!(minus.linear().unwrap().b()[(1, 0)].is_sign_negative());
        assert_ne!(minus.fingerprint(), plus);
        // TOML's `-0.0` is the negative zero too.
        assert_eq!(from_toml(&n, "").fingerprint(), minus.fingerprint());
        n.b[1][0] = 0.0;
        assert_eq!(from_toml(&n, "").fingerprint(), plus);
    }
}
