//! What an estimator needs to know, and nothing a simulator needs: an [`EstimatorSpec`].
//!
//! The model (a [`LinearModel`] with an optional known input, or seed 003's coupled-noise
//! model), the prior the estimators start from, what they know of the channel
//! ([`channel::ChannelKnowledge`]: occlusion regions, token bucket, event triggers, Tobit
//! thresholds), and the runner's options that belong to the deployment (a known loss rate, the
//! innovation gate). A simulated scenario *produces* one (channel-sim's
//! `Scenario::estimator_spec`); an engineer with real sensors writes one in TOML
//! ([`file::load`], docs/pipeline.md "Estimator specs") and runs `ipc-runner run
//! --estimator-spec FILE`. The runner's estimators are built from the spec alone, and the
//! stream header's model fingerprint is the spec's ([`EstimatorSpec::fingerprint`]), so a
//! foreign publisher and a spec file that agree are accepted.
//!
//! | module | what |
//! |---|---|
//! | [`linear`] | the linear-Gaussian model, its effective covariances formed once |
//! | [`control`] | a known control input `B_u u_k` and its schedule |
//! | [`channel`] | what the estimators know of the channel |
//! | [`file`](mod@file) | the TOML form, every field validated and named in errors |
//! | [`overflow`] | refusing finite numbers whose moments overflow |
//! | [`fingerprint`] | the stream's model fingerprint |
//! | [`validate`], [`error`] | the checks and the one error type |

pub mod channel;
pub mod control;
pub mod error;
pub mod file;
pub mod fingerprint;
pub mod linear;
pub mod overflow;
pub mod validate;

pub use channel::ChannelKnowledge;
pub use control::{Control, Schedule};
pub use error::SpecError;
pub use linear::{LinearModel, Sensor};

use estpipe_wire::StreamHeader;
use nalgebra::{DMatrix, DVector};

use crate::validate::{check_pd, check_shape};

/// The estimators' model of the plant and its sensors.
// One per spec, built once and shared behind an `Arc`: the size of the small variant does not
// matter, and boxing `Linear` would change every match on it in the workspace.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq)]
pub enum Model {
    /// A linear-Gaussian model, possibly with a known control input.
    Linear(LinearModel),
    /// Seed 003's model (eq. 1): `x_{k+1} = A_k x_k + f(x_k) + B_k w_k`, `y_k = C_k x_k +
    /// D_k w_k` with one scalar `w_k ~ N(0, w̄²)` driving both; its matrices and `f` are the
    /// paper's fixed example (the core's `Seed003Example`), only `w̄²` is a parameter.
    Seed003 {
        /// w̄², the variance of the scalar noise.
        w_var: f64,
    },
}

/// Seed 003's dimensions (the core's `Seed003Example`): n_x, n_y, one node.
pub const SEED003_DIMS: (usize, usize) = (3, 2);

/// The estimators' prior: x̂₀ and P₀.
#[derive(Clone, Debug, PartialEq)]
pub struct Prior {
    /// x̂₀.
    pub mean: DVector<f64>,
    /// P₀, symmetric positive definite.
    pub cov: DMatrix<f64>,
}

/// Everything an estimator needs, nothing a simulator needs (see the crate documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct EstimatorSpec {
    /// A name for reports and the stream header (informational: not part of the fingerprint).
    pub name: String,
    /// The model.
    pub model: Model,
    /// The prior.
    pub prior: Prior,
    /// What the estimators know of the channel.
    pub channel: ChannelKnowledge,
    /// A known probability that a slot is lost in transport, for a receiver that cannot tell a
    /// loss from a channel dropout (`--loss-rate`; the occlusion estimators' `-mix` variants).
    pub loss_rate: Option<f64>,
    /// The innovation gate's probability (`--gate`, docs/gate.md).
    pub gate: Option<f64>,
}

impl EstimatorSpec {
    /// Validates the parts against each other: the prior against n_x, every per-node part of
    /// the channel against the nodes and their n_y. Errors name the TOML field.
    pub fn new(
        name: impl Into<String>,
        model: Model,
        prior: Prior,
        channel: ChannelKnowledge,
    ) -> Result<Self, SpecError> {
        let spec = Self {
            name: name.into(),
            model,
            prior,
            channel,
            loss_rate: None,
            gate: None,
        };
        spec.check()?;
        Ok(spec)
    }

    /// With a known loss rate in `[0, 1)` (`loss_rate`).
    pub fn with_loss_rate(mut self, p: Option<f64>) -> Result<Self, SpecError> {
        if let Some(p) = p {
            if !(p.is_finite() && (0.0..1.0).contains(&p)) {
                return Err(SpecError::invalid(
                    "loss_rate",
                    format!("must be a probability in [0, 1), got {p}"),
                ));
            }
        }
        self.loss_rate = p;
        Ok(self)
    }

    /// With the innovation gate of probability `p` in `(0, 1)` (`gate`).
    pub fn with_gate(mut self, p: Option<f64>) -> Result<Self, SpecError> {
        if let Some(p) = p {
            if !(p.is_finite() && p > 0.0 && p < 1.0) {
                return Err(SpecError::invalid(
                    "gate",
                    format!("must be a probability in (0, 1), got {p}"),
                ));
            }
        }
        self.gate = p;
        Ok(self)
    }

    fn check(&self) -> Result<(), SpecError> {
        let nx = self.nx();
        if let Model::Seed003 { w_var } = self.model {
            if !(w_var.is_finite() && w_var > 0.0) {
                return Err(SpecError::invalid(
                    "model.w_var",
                    format!("must be a positive variance, got {w_var}"),
                ));
            }
        }
        if self.prior.mean.len() != nx || self.prior.mean.iter().any(|v| !v.is_finite()) {
            return Err(SpecError::invalid(
                "prior.mean",
                format!("must have nx = {nx} finite entries"),
            ));
        }
        check_shape(self.prior.cov.shape(), (nx, nx), "prior.cov")?;
        check_pd(&self.prior.cov, "prior.cov")?;
        let per_node = |field: &str, got: usize| {
            if got == self.nodes() {
                Ok(())
            } else {
                Err(SpecError::invalid(
                    field,
                    format!(
                        "must have one entry per sensor node ({}), got {got}",
                        self.nodes()
                    ),
                ))
            }
        };
        let node_vector = |field: String, m: usize, got: usize| {
            let ny = self.node_ny(m);
            if got == ny {
                Ok(())
            } else {
                Err(SpecError::invalid(
                    field,
                    format!("must have ny = {ny} entries (node {m}'s), got {got}"),
                ))
            }
        };
        let c = &self.channel;
        if let Some(o) = &c.occlusion {
            if o.e().len() != nx {
                return Err(SpecError::invalid(
                    "occlusion.e",
                    format!("must be {nx} finite entries"),
                ));
            }
        }
        if let Some(t) = &c.tobit {
            per_node("tobit.thresholds", t.nodes())?;
            for m in 0..t.nodes() {
                node_vector(format!("tobit.thresholds[{m}]"), m, t.tau(m).len())?;
            }
        }
        if let Some(t) = &c.event_trigger {
            per_node("event_trigger.nodes", t.nodes())?;
            for m in 0..t.nodes() {
                node_vector(
                    format!("event_trigger.nodes[{m}].reference"),
                    m,
                    t.reference(m).len(),
                )?;
            }
        }
        Ok(())
    }

    /// n_x.
    pub fn nx(&self) -> usize {
        match &self.model {
            Model::Linear(l) => l.nx(),
            Model::Seed003 { .. } => SEED003_DIMS.0,
        }
    }

    /// The number of sensor nodes.
    pub fn nodes(&self) -> usize {
        match &self.model {
            Model::Linear(l) => l.nodes(),
            Model::Seed003 { .. } => 1,
        }
    }

    /// n_y of node `node`.
    pub fn node_ny(&self, node: usize) -> usize {
        match &self.model {
            Model::Linear(l) => l.node_ny(node),
            Model::Seed003 { .. } => SEED003_DIMS.1,
        }
    }

    /// The largest node's n_y (the estimators are sized for it).
    pub fn ny(&self) -> usize {
        (0..self.nodes())
            .map(|m| self.node_ny(m))
            .max()
            .unwrap_or(0)
    }

    /// The linear model, if the model is one.
    pub fn linear(&self) -> Option<&LinearModel> {
        match &self.model {
            Model::Linear(l) => Some(l),
            Model::Seed003 { .. } => None,
        }
    }

    /// The model fingerprint of the stream (docs/wire.md, "Model fingerprint").
    pub fn fingerprint(&self) -> u64 {
        fingerprint::fingerprint(self)
    }

    /// The header a stream for these estimators carries: the name, nodes, n_x, n_y per node
    /// and [`EstimatorSpec::fingerprint`].
    pub fn stream_header(&self) -> StreamHeader {
        let ny: Vec<usize> = (0..self.nodes()).map(|m| self.node_ny(m)).collect();
        StreamHeader::new(&self.name, self.nodes(), self.nx(), &ny, self.fingerprint())
    }

    /// Warnings about parameters accepted against their paper's own conditions (the event
    /// trigger's λχ ≤ 1 by explicit opt-in), one line each.
    pub fn warnings(&self) -> Vec<String> {
        self.channel
            .event_trigger
            .as_ref()
            .map(|t| t.warnings())
            .unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::channel::{Occlusion, TobitCensoring, TriggerParams, TriggeredTokenBucket};
    use nalgebra::{dmatrix, dvector};

    /// nx = 2; node 0 of ny = 1, node 1 of ny = 2.
    fn model() -> Model {
        let sensors = vec![
            Sensor {
                c: dmatrix![1.0, 0.0],
                d: dmatrix![1.0],
                r: dmatrix![0.25],
            },
            Sensor {
                c: dmatrix![1.0, 0.0; 0.0, 1.0],
                d: DMatrix::identity(2, 2),
                r: dmatrix![0.5, 0.0; 0.0, 0.5],
            },
        ];
        Model::Linear(
            LinearModel::new(
                dmatrix![0.95, 0.1; -0.1, 0.95],
                DMatrix::identity(2, 2),
                dmatrix![0.01, 0.0; 0.0, 0.04],
                sensors,
            )
            .unwrap(),
        )
    }

    fn prior() -> Prior {
        Prior {
            mean: dvector![0.0, 0.0],
            cov: DMatrix::identity(2, 2),
        }
    }

    fn trigger(references: Vec<Vec<f64>>) -> TriggeredTokenBucket {
        let p = TriggerParams {
            sigma: 0.5,
            chi: 5.0,
            lambda: 0.5,
            eta0: 1.0,
        };
        let n = references.len();
        TriggeredTokenBucket::new(&vec![p; n], references, 3, 2, 6, vec![1; n], false).unwrap()
    }

    fn refused(prior: Prior, channel: ChannelKnowledge, field: &str) {
        let e = EstimatorSpec::new("t", model(), prior, channel)
            .unwrap_err()
            .to_string();
        assert!(e.contains(&format!("invalid `{field}`:")), "{field}: {e}");
        assert!(!e.contains('\n'));
    }

    #[test]
    fn new_refuses_parts_that_do_not_fit_naming_the_field() {
        let ok = EstimatorSpec::new("t", model(), prior(), ChannelKnowledge::default()).unwrap();
        assert_eq!((ok.nx(), ok.nodes(), ok.node_ny(1), ok.ny()), (2, 2, 2, 2));
        let none = ChannelKnowledge::default;
        let p = |mean: DVector<f64>, cov: DMatrix<f64>| Prior { mean, cov };
        refused(
            p(dvector![0.0], DMatrix::identity(2, 2)),
            none(),
            "prior.mean",
        );
        refused(
            p(dvector![0.0, 0.0, 0.0], DMatrix::identity(2, 2)),
            none(),
            "prior.mean",
        );
        refused(
            p(dvector![f64::NAN, 0.0], DMatrix::identity(2, 2)),
            none(),
            "prior.mean",
        );
        refused(
            p(dvector![0.0, 0.0], DMatrix::identity(3, 3)),
            none(),
            "prior.cov",
        );
        refused(
            p(dvector![0.0, 0.0], DMatrix::identity(2, 3)),
            none(),
            "prior.cov",
        );
        refused(
            p(dvector![0.0, 0.0], dmatrix![1.0, 2.0; 2.0, 1.0]),
            none(),
            "prior.cov",
        );

        let with = |f: &dyn Fn(&mut ChannelKnowledge)| {
            let mut c = ChannelKnowledge::default();
            f(&mut c);
            c
        };
        // An occlusion E built for nx = 3.
        let occ = Occlusion::new(vec![1.0, 0.0, 0.0], 0.1, vec![0.0], vec![1.0], 3).unwrap();
        refused(
            prior(),
            with(&|c| c.occlusion = Some(occ.clone())),
            "occlusion.e",
        );
        let tobit = |t: Vec<Vec<f64>>| TobitCensoring::new(t).unwrap();
        refused(
            prior(),
            with(&|c| c.tobit = Some(tobit(vec![vec![0.0]]))),
            "tobit.thresholds",
        );
        refused(
            prior(),
            with(&|c| c.tobit = Some(tobit(vec![vec![0.0], vec![0.0], vec![0.0]]))),
            "tobit.thresholds",
        );
        refused(
            prior(),
            with(&|c| c.tobit = Some(tobit(vec![vec![0.0, 0.0], vec![0.0, 0.0]]))),
            "tobit.thresholds[0]",
        );
        refused(
            prior(),
            with(&|c| c.tobit = Some(tobit(vec![vec![0.0], vec![0.0]]))),
            "tobit.thresholds[1]",
        );
        refused(
            prior(),
            with(&|c| c.event_trigger = Some(trigger(vec![vec![0.0]]))),
            "event_trigger.nodes",
        );
        refused(
            prior(),
            with(&|c| c.event_trigger = Some(trigger(vec![vec![0.0], vec![0.0]]))),
            "event_trigger.nodes[1].reference",
        );
        // Fitting parts are accepted.
        let fits = with(&|c| {
            c.tobit = Some(tobit(vec![vec![0.0], vec![0.0, 1.0]]));
            c.event_trigger = Some(trigger(vec![vec![0.0], vec![0.0, 0.0]]));
        });
        EstimatorSpec::new("t", model(), prior(), fits).unwrap();

        // Seed 003: w̄² must be a positive variance; n_x = 3.
        let seed = |w_var: f64| {
            EstimatorSpec::new(
                "s",
                Model::Seed003 { w_var },
                Prior {
                    mean: DVector::zeros(3),
                    cov: DMatrix::identity(3, 3),
                },
                ChannelKnowledge::default(),
            )
        };
        assert_eq!(seed(0.5).unwrap().nx(), 3);
        for w in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(seed(w).unwrap_err().to_string().contains("`model.w_var`"));
        }
    }

    #[test]
    fn loss_rate_and_gate_are_probabilities() {
        let s = || EstimatorSpec::new("t", model(), prior(), ChannelKnowledge::default()).unwrap();
        for p in [0.0, 0.5, 1.0 - f64::EPSILON] {
            assert_eq!(s().with_loss_rate(Some(p)).unwrap().loss_rate, Some(p));
        }
        for p in [
            -f64::MIN_POSITIVE,
            -1e-300,
            1.0,
            f64::NAN,
            f64::INFINITY,
            1e308,
        ] {
            let e = s().with_loss_rate(Some(p)).unwrap_err().to_string();
            assert!(e.contains("`loss_rate`"), "{p}: {e}");
        }
        for p in [f64::MIN_POSITIVE, 0.5, 1.0 - f64::EPSILON] {
            assert_eq!(s().with_gate(Some(p)).unwrap().gate, Some(p));
        }
        for p in [0.0, -0.0, 1.0, -0.5, f64::NAN, f64::NEG_INFINITY] {
            let e = s().with_gate(Some(p)).unwrap_err().to_string();
            assert!(e.contains("`gate`"), "{p}: {e}");
        }
        assert_eq!(s().with_gate(None).unwrap().gate, None);
    }

    #[test]
    fn the_stream_header_carries_the_dimensions_and_the_fingerprint() {
        let s = EstimatorSpec::new("hdr", model(), prior(), ChannelKnowledge::default()).unwrap();
        let h = s.stream_header();
        let want = StreamHeader::new("hdr", 2, 2, &[1, 2], s.fingerprint());
        assert_eq!(h, want);
    }
}
