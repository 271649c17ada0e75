//! Wrong intentions from wrong poses (the paper's most common real-robot failure, §5: AMCL's
//! error makes the planner say `GoForward` at a junction that needs `TurnLeft`).
//!
//! Every cycle the run asks the same intention pipeline twice: once with the pose the agent
//! published (what the robot is told) and once with the true pose (what it should have been
//! told). [`Auditor`] compares the two DLMs, cycle by cycle, and keeps what a reader needs: how
//! often they differ, how often a needed turn was missed or reversed, how often such a mistake
//! lasted long enough to matter (an *event*: at least [`EVENT_CYCLES`] cycles in a row) and
//! whether the controller got through an event without an intervention. Plain data in, counts
//! out; no clock, no I/O.

use protocol::Dlm;
use serde::{Deserialize, Serialize};

/// Consecutive wrong-turn cycles (0.5 s at 10 Hz) that make an event: a one-cycle flicker at a
/// DLM threshold is not a wrong instruction anyone would act on.
pub const EVENT_CYCLES: u32 = 5;
/// An intervention this soon after an event began is blamed on it.
pub const BLAME_S: f64 = 10.0;

/// The comparison over one run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IntentionAudit {
    /// Cycles where both poses got a plan to the same goal.
    pub cycles: u64,
    /// Cycles whose DLMs differ in any way.
    pub dlm_differs: u64,
    /// Cycles where the truth needed a turn and the robot was told `GoForward`.
    pub turn_missed: u64,
    /// Cycles where the robot was told the opposite turn, or a turn where the truth went on.
    pub turn_wrong: u64,
    /// Runs of at least [`EVENT_CYCLES`] missed or wrong-turn cycles.
    pub events: u32,
    /// Events followed by an intervention within [`BLAME_S`].
    pub events_with_intervention: u32,
    /// Mean position error of the published pose in the cycles whose DLMs differ (0 if none).
    pub mean_error_when_differs_m: f64,
    /// Mean position error of the published pose in the cycles whose DLMs agree.
    pub mean_error_when_agrees_m: f64,
}

/// What a pair of DLMs says about the published one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Same,
    /// Differs, but not about turning (e.g. `Stop` against `GoForward` near a goal).
    Other,
    TurnMissed,
    TurnWrong,
}

/// Classifies the published DLM against the true one.
#[must_use]
pub fn verdict(published: Dlm, truth: Dlm) -> Verdict {
    use Dlm::{GoForward, TurnLeft, TurnRight};
    match (published, truth) {
        (p, t) if p == t => Verdict::Same,
        (GoForward, TurnLeft | TurnRight) => Verdict::TurnMissed,
        (TurnLeft, TurnRight) | (TurnRight, TurnLeft) | (TurnLeft | TurnRight, GoForward) => {
            Verdict::TurnWrong
        }
        _ => Verdict::Other,
    }
}

/// The running comparison.
#[derive(Debug, Default)]
pub struct Auditor {
    audit: IntentionAudit,
    sum_differs_m: f64,
    sum_agrees_m: f64,
    /// Length of the current run of missed/wrong-turn cycles.
    streak: u32,
    /// Start times of events not yet settled (an intervention within [`BLAME_S`], or not).
    open_events_s: Vec<f64>,
}

impl Auditor {
    /// One cycle at `t_s`: the two DLMs and the published pose's position error.
    pub fn on_cycle(&mut self, t_s: f64, published: Dlm, truth: Dlm, error_m: f64) {
        self.settle(t_s);
        let v = verdict(published, truth);
        let a = &mut self.audit;
        a.cycles += 1;
        if v == Verdict::Same {
            self.sum_agrees_m += error_m;
        } else {
            a.dlm_differs += 1;
            self.sum_differs_m += error_m;
        }
        match v {
            Verdict::TurnMissed => a.turn_missed += 1,
            Verdict::TurnWrong => a.turn_wrong += 1,
            Verdict::Same | Verdict::Other => {}
        }
        if matches!(v, Verdict::TurnMissed | Verdict::TurnWrong) {
            self.streak += 1;
            if self.streak == EVENT_CYCLES {
                a.events += 1;
                #[allow(clippy::cast_precision_loss)]
                let began_s = t_s - 0.1 * f64::from(EVENT_CYCLES - 1);
                self.open_events_s.push(began_s);
            }
        } else {
            self.streak = 0;
        }
    }

    /// A human intervention at `t_s`: it settles every open event.
    pub fn on_intervention(&mut self, t_s: f64) {
        let blamed = self
            .open_events_s
            .iter()
            .filter(|&&s| t_s - s <= BLAME_S)
            .count();
        #[allow(clippy::cast_possible_truncation)]
        {
            self.audit.events_with_intervention += blamed as u32;
        }
        self.open_events_s.clear();
        self.streak = 0;
    }

    /// Forgets events older than [`BLAME_S`] at `t_s`: they passed without an intervention.
    fn settle(&mut self, t_s: f64) {
        self.open_events_s.retain(|&s| t_s - s <= BLAME_S);
    }

    #[must_use]
    pub fn finish(self) -> IntentionAudit {
        self.audit.with_means(self.sum_differs_m, self.sum_agrees_m)
    }
}

impl IntentionAudit {
    /// The audit with its mean errors set from the sums of the errors over its differing and
    /// agreeing cycles.
    #[must_use]
    fn with_means(mut self, sum_differs_m: f64, sum_agrees_m: f64) -> Self {
        #[allow(clippy::cast_precision_loss)]
        {
            if self.dlm_differs > 0 {
                self.mean_error_when_differs_m = sum_differs_m / self.dlm_differs as f64;
            }
            let agree = self.cycles - self.dlm_differs;
            if agree > 0 {
                self.mean_error_when_agrees_m = sum_agrees_m / agree as f64;
            }
        }
        self
    }

    /// The audits of several runs as one (the mean errors weighted by their cycles); `None`
    /// for none.
    #[must_use]
    pub fn sum<'a>(audits: impl IntoIterator<Item = &'a IntentionAudit>) -> Option<Self> {
        let mut total: Option<Self> = None;
        let (mut differs_m, mut agrees_m) = (0.0, 0.0);
        for a in audits {
            let t = total.get_or_insert_with(Self::default);
            t.cycles += a.cycles;
            t.dlm_differs += a.dlm_differs;
            t.turn_missed += a.turn_missed;
            t.turn_wrong += a.turn_wrong;
            t.events += a.events;
            t.events_with_intervention += a.events_with_intervention;
            #[allow(clippy::cast_precision_loss)]
            {
                differs_m += a.mean_error_when_differs_m * a.dlm_differs as f64;
                agrees_m += a.mean_error_when_agrees_m * (a.cycles - a.dlm_differs) as f64;
            }
        }
        total.map(|t| t.with_means(differs_m, agrees_m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Dlm::{GoForward, Stop, TurnLeft, TurnRight};

    #[test]
    fn verdicts_name_what_went_wrong() {
        assert_eq!(verdict(TurnLeft, TurnLeft), Verdict::Same);
        assert_eq!(verdict(GoForward, TurnLeft), Verdict::TurnMissed);
        assert_eq!(verdict(GoForward, TurnRight), Verdict::TurnMissed);
        assert_eq!(verdict(TurnRight, TurnLeft), Verdict::TurnWrong);
        assert_eq!(verdict(TurnLeft, GoForward), Verdict::TurnWrong);
        assert_eq!(verdict(Stop, GoForward), Verdict::Other);
        assert_eq!(verdict(GoForward, Stop), Verdict::Other);
    }

    fn cycles(a: &mut Auditor, from_s: f64, n: u32, published: Dlm, truth: Dlm, err_m: f64) -> f64 {
        let mut t = from_s;
        for _ in 0..n {
            a.on_cycle(t, published, truth, err_m);
            t += 0.1;
        }
        t
    }

    #[test]
    fn a_flicker_is_counted_but_is_no_event() {
        let mut a = Auditor::default();
        let t = cycles(&mut a, 0.0, 10, GoForward, GoForward, 0.05);
        let t = cycles(&mut a, t, EVENT_CYCLES - 1, GoForward, TurnLeft, 0.3);
        cycles(&mut a, t, 10, TurnLeft, TurnLeft, 0.05);
        let r = a.finish();
        assert_eq!(r.cycles, 20 + u64::from(EVENT_CYCLES - 1));
        assert_eq!(r.turn_missed, u64::from(EVENT_CYCLES - 1));
        assert_eq!(r.events, 0);
        assert!((r.mean_error_when_differs_m - 0.3).abs() < 1e-12);
        assert!((r.mean_error_when_agrees_m - 0.05).abs() < 1e-12);
    }

    #[test]
    fn events_are_blamed_for_interventions_soon_after_only() {
        let mut a = Auditor::default();
        // Event 1, then an intervention 3 s later: blamed.
        let t = cycles(&mut a, 0.0, 8, GoForward, TurnLeft, 0.4);
        a.on_intervention(t + 3.0);
        // Event 2, then 20 s of correct driving, then an intervention: not blamed.
        let t = cycles(&mut a, t + 3.0, 8, TurnRight, TurnLeft, 0.4);
        let t = cycles(&mut a, t, 200, GoForward, GoForward, 0.05);
        a.on_intervention(t);
        let r = a.finish();
        assert_eq!(r.events, 2);
        assert_eq!(r.events_with_intervention, 1);
        assert_eq!(r.turn_missed, 8);
        assert_eq!(r.turn_wrong, 8);
    }

    #[test]
    fn summed_audits_weight_the_mean_errors_by_cycles() {
        let mut a = Auditor::default();
        cycles(&mut a, 0.0, 10, GoForward, TurnLeft, 0.5);
        cycles(&mut a, 1.0, 30, GoForward, GoForward, 0.1);
        let mut b = Auditor::default();
        cycles(&mut b, 0.0, 30, GoForward, TurnLeft, 0.1);
        cycles(&mut b, 3.0, 10, GoForward, GoForward, 0.3);
        let (a, b) = (a.finish(), b.finish());
        let t = IntentionAudit::sum([&a, &b]).unwrap();
        assert_eq!((t.cycles, t.dlm_differs, t.turn_missed), (80, 40, 40));
        assert!((t.mean_error_when_differs_m - (10.0 * 0.5 + 30.0 * 0.1) / 40.0).abs() < 1e-12);
        assert!((t.mean_error_when_agrees_m - (30.0 * 0.1 + 10.0 * 0.3) / 40.0).abs() < 1e-12);
        assert_eq!(IntentionAudit::sum([]), None);
    }
}
