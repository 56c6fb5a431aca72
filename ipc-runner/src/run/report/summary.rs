//! The summary a person reads at the end of a run: the stream, the estimators, the latency.

use super::RunReport;
use crate::estimators::role::{figure, Role, MSE_NOTE};

impl RunReport {
    /// The summary a person reads at the end of a run.
    pub fn summary(&self) -> String {
        let mut s = self.stream_lines();
        if self.counts.instants == 0 {
            // Nothing was estimated: no table of NaN (the line above and the error say why).
            s.push_str("no instant processed: no estimates, no latency\n");
            return s;
        }
        self.estimator_table(&mut s);
        for e in &self.estimators {
            if let Some(g) = e.gate {
                s.push_str(&format!(
                    "{}: innovation gate rejected {} of {} measurements\n",
                    e.name, g.rejected, g.tested
                ));
            }
        }
        s.push_str(&self.latency.table());
        if let Some(a) = self.allocations_after_warmup {
            s.push_str(&format!(
                "allocations after warm-up: {a} over {} slots ({} estimates published)\n",
                self.slots_after_warmup, self.published_after_warmup
            ));
        }
        for w in &self.warnings {
            s.push_str(w);
            s.push('\n');
        }
        s
    }

    /// What arrived and what did not: the slots by their fate, the publisher's losses and
    /// stalls.
    fn stream_lines(&self) -> String {
        let c = &self.counts;
        let mut s = format!(
            "scenario {} · {} instants · {} wait · ended: {:?}\n\
             slots: {} received ({} delivered, {} dropped by the channel), {} lost in IPC, {} missed before join\n",
            self.scenario,
            c.instants,
            self.wait.as_str(),
            self.ending,
            c.received,
            c.delivered,
            c.dropped_by_channel,
            c.lost_in_ipc,
            c.missed_before_join,
        );
        if let Some(e) = &self.error {
            s.push_str(&format!("failed: {e}\n"));
        }
        if self.truth_nonfinite > 0 {
            s.push_str(&format!(
                "truth not finite at {} instant(s): left out of every MSE\n",
                self.truth_nonfinite
            ));
        }
        let lost_other = c.lost_deadline + c.lost_overrun + c.lost_after_end;
        if lost_other + c.late + c.out_of_order > 0 {
            s.push_str(&format!(
                "slots lost by the instant deadline {}, by overrun {}, after a node's end {}; \
                 {} late, {} duplicate\n",
                c.lost_deadline, c.lost_overrun, c.lost_after_end, c.late, c.out_of_order
            ));
        }
        if c.skipped.total() > 0 {
            s.push_str(&format!(
                "slots skipped: {} ({})\n",
                c.skipped.total(),
                c.skipped.describe()
            ));
        }
        if c.anomalies.period_ns + c.anomalies.send_ns > 0 {
            s.push_str(&format!(
                "fields ignored: period_ns {}, send_ns {}\n",
                c.anomalies.period_ns, c.anomalies.send_ns
            ));
        }
        if self.sessions > 1 || self.publisher_losses > 0 {
            s.push_str(&format!(
                "publisher lost {} time(s); {} session(s)\n",
                self.publisher_losses, self.sessions
            ));
        }
        let st = &self.stalls;
        if st.count > 0 {
            s.push_str(&format!(
                "publisher stalled {} time(s) (alive but silent past the deadline): longest \
                 {:.1} ms, {:.1} ms in all\n",
                st.count, st.longest_ms, st.total_ms
            ));
        }
        s
    }

    /// One row per estimator: role, MSE against the truth, instants, rejections; then why
    /// there is no MSE when no instant had a truth, and the note on reading them.
    fn estimator_table(&self, s: &mut String) {
        // The name column fits the longest name (`fused-predict+gate`), 16 at least.
        let w = (self.estimators.iter())
            .map(|e| e.name.chars().count())
            .fold(16, usize::max);
        s.push_str(&format!(
            "{:<w$} {:<9} {:>13} {:>10} {:>10}\n",
            "estimator", "role", "MSE vs truth", "instants", "rejected"
        ));
        for e in &self.estimators {
            // An MSE over no instant is not a number worth printing.
            let mse = if e.mse_instants > 0 {
                figure(e.mse, 13)
            } else {
                format!("{:>13}", "-")
            };
            s.push_str(&format!(
                "{:<w$} {:<9} {mse} {:>10} {:>10}\n",
                e.name,
                Role::of(&e.name),
                e.mse_instants,
                e.rejected
            ));
        }
        if self.estimators.iter().all(|e| e.mse_instants == 0) && !self.estimators.is_empty() {
            s.push_str(&format!(
                "no truth: MSE not computed ({} of {} instants had no truth message: only \
                 channel-sim publishes <prefix>/truth, a publisher of your own need not; \
                 docs/wire.md)\n",
                self.truth_missing, self.counts.instants
            ));
        }
        if !self.estimators.is_empty() {
            s.push_str(MSE_NOTE);
        }
    }
}
