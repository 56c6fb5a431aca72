//! What the receiver knows of one node's dynamic event trigger (seed 004, eqs. 11-15): the
//! reference the node compares with and the largest threshold the trigger can have, hence
//! the *silence set* of an instant at which the node held its trigger
//! (docs/tobit-fusion.md, "Silence that speaks").
//!
//! A node that did not fire has `‖ε_t‖ < η_t/χ + σ` (14): its measurement lies in the ball of
//! radius `η_t/χ + σ` around the reference (the last measurement it transmitted, which the
//! receiver holds). η depends on `‖ε‖` at instants whose measurement was never sent, so the
//! receiver cannot know it; it keeps an upper bound η̄ ≥ η and uses the ball of radius
//! `r̄ = η̄/χ + σ`, which contains the true set (an outer set: conservative, never wrong).
//!
//! ```text
//! η_{t+1} = λ η_t + σ − ‖ε_t‖ ≤ λ η̄_t + σ            (13), ‖ε_t‖ ≥ 0        (K1)
//! sent at t: (14) held, η_t ≤ χ (‖ε_t‖ − σ)           with ‖ε_t‖ = ‖ȳ − y_t‖ known   (K2)
//! η̄_{t+1} = λ min(η̄_t, χ(‖ε_t‖ − σ)) + σ  (sent),   λ η̄_t + σ  (otherwise),   η̄_0 = η_0
//! ```
//!
//! (13) uses ε after the decision (0 when sent; docs/design.md, "Seed 004"), so η_{t+1} =
//! λη_t + σ exactly after a send, and the bound (K2) tightens η̄ with the one ε the receiver
//! sees. With λ < 1 the bound forgets its start geometrically (the example's λ ≤ 0.2: within
//! a few instants), so carrying η in the packets would tighten it only for instants right
//! after a send; the wire does not carry it.
//!
//! A packet lost in transport may have been a transmission, which would have moved the
//! reference to a measurement the receiver never saw: the reference is then unknown and no
//! silence set exists until the node's next delivered packet.

use nalgebra::SVector;

use super::event_trigger::EventTriggerConfig;
use crate::linalg::check_finite;
use crate::{Error, Real, Result};

/// The silence set of one instant: `‖y − centre‖ < radius` (14).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SilenceBall<T: Real, const NY: usize> {
    /// The reference ȳ (the last transmitted measurement).
    pub centre: SVector<T, NY>,
    /// `η̄/χ + σ` (> 0).
    pub radius: T,
}

/// The receiver's knowledge of one node's trigger.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriggerKnowledge<T: Real, const NY: usize> {
    cfg: EventTriggerConfig<T>,
    eta_max: T,
    reference: SVector<T, NY>,
    reference_known: bool,
}

impl<T: Real, const NY: usize> TriggerKnowledge<T, NY> {
    /// Starts where the node starts: η̄ = η₀ and the node's initial reference.
    pub fn new(cfg: EventTriggerConfig<T>, initial_reference: SVector<T, NY>) -> Result<Self> {
        check_finite(&initial_reference, "initial reference")?;
        Ok(Self {
            cfg,
            eta_max: cfg.eta0(),
            reference: initial_reference,
            reference_known: true,
        })
    }

    /// The upper bound η̄ on this instant's η.
    #[inline]
    pub fn eta_max(&self) -> T {
        self.eta_max
    }

    /// The reference, if known.
    #[inline]
    pub fn reference(&self) -> Option<&SVector<T, NY>> {
        self.reference_known.then_some(&self.reference)
    }

    /// The silence set of this instant (an outer ball), if the reference is known and the
    /// largest threshold is positive (otherwise the node could not have held: a silence is
    /// then no information this knowledge can use).
    #[must_use]
    pub fn silence_set(&self) -> Option<SilenceBall<T, NY>> {
        let radius = self.eta_max / self.cfg.chi() + self.cfg.sigma();
        (self.reference_known && radius > T::zero()).then_some(SilenceBall {
            centre: self.reference,
            radius,
        })
    }

    /// The node's measurement `y` arrived (K2, then (13)). Unchanged on error.
    pub fn delivered(&mut self, y: &SVector<T, NY>) -> Result<()> {
        check_finite(y, "measurement")?;
        let mut eta = self.eta_max;
        if self.reference_known {
            let fired_below = self.cfg.chi() * ((self.reference - y).norm() - self.cfg.sigma());
            if fired_below < eta {
                eta = fired_below;
            }
        }
        let next = self.cfg.lambda() * eta + self.cfg.sigma();
        if !next.finite() {
            return Err(Error::NonFinite {
                what: "trigger eta bound",
            });
        }
        self.eta_max = next;
        self.reference = *y;
        self.reference_known = true;
        Ok(())
    }

    /// The node sent nothing and nothing was lost (held or blocked): (K1).
    pub fn silent(&mut self) {
        self.eta_max = self.cfg.lambda() * self.eta_max + self.cfg.sigma();
    }

    /// The node's packet was lost in transport: (K1), and the reference becomes unknown.
    pub fn lost(&mut self) {
        self.silent();
        self.reference_known = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::event_trigger::EventTrigger;
    use nalgebra::vector;

    #[test]
    fn the_bound_is_never_below_the_nodes_eta_and_the_set_contains_every_held_measurement() {
        // The paper's node 2 (σ = 0.2, λ = 0.2, χ = 5, η₀ = 1.5; λχ = 1, so η goes negative)
        // and a λχ > 1 node, each granted at every other instant, on an irregular signal.
        for cfg in [
            EventTriggerConfig::new_allowing_paper_violation(0.2, 5.0, 0.2, 1.5).unwrap(),
            EventTriggerConfig::new(0.3, 5.0, 0.4, 1.0).unwrap(),
        ] {
            let mut node = EventTrigger::<f64, 2>::new(cfg, vector![0.0, 0.0]).unwrap();
            let mut know = TriggerKnowledge::new(cfg, vector![0.0, 0.0]).unwrap();
            let mut held = 0;
            for t in 0..3000 {
                let s = t as f64;
                let y = vector![
                    (0.07 * s).sin() * 2.0,
                    (0.05 * s).cos() + 0.3 * (0.9 * s).sin()
                ];
                assert!(know.eta_max() >= node.eta() - 1e-12, "t = {t}");
                let set = know.silence_set();
                let o = node.step(&y, t % 2 == 0).unwrap();
                if o.sent {
                    know.delivered(&y).unwrap();
                } else {
                    if !o.triggered {
                        let b = set.unwrap();
                        assert!((y - b.centre).norm() < b.radius, "t = {t}");
                        held += 1;
                    }
                    know.silent();
                }
                assert_eq!(know.reference(), Some(node.reference()));
            }
            assert!(held > 100, "held {held}");
        }
    }

    #[test]
    fn a_loss_hides_the_reference_until_the_next_delivery() {
        let cfg = EventTriggerConfig::new(0.5, 4.0, 0.5, 2.0).unwrap();
        let mut k = TriggerKnowledge::<f64, 1>::new(cfg, vector![0.0]).unwrap();
        // Radius η̄/χ + σ = 2/4 + 0.5.
        assert_eq!(k.silence_set().unwrap().radius, 1.0);
        k.lost();
        assert!(k.silence_set().is_none());
        // η̄ = 0.5·2 + 0.5 = 1.5; a delivery with unknown reference does not tighten it.
        k.delivered(&vector![3.0]).unwrap();
        assert_eq!(k.eta_max(), 0.5 * 1.5 + 0.5);
        // Known reference 3.0, y = 3.6: η ≤ 4 (0.6 − 0.5) = 0.4 < η̄ = 1.25 → η̄ = 0.2 + 0.5.
        k.delivered(&vector![3.6]).unwrap();
        assert!((k.eta_max() - 0.7).abs() < 1e-15);
        assert_eq!(k.reference(), Some(&vector![3.6]));
        let before = k;
        assert!(k.delivered(&vector![f64::NAN]).is_err());
        assert_eq!(k, before);
    }
}
