//! The viewer's link answers for the evaluations on its host.
//!
//! At the goal the rover waits for every reader of its estimates to acknowledge its
//! last sample ([`dyfos_mission::rover`]): a reader that has not taken the sample
//! when the rover's ports close loses it. Across two hosts the rover's only reader
//! is its own link, which forwards the samples, so the viewer's link acknowledges in
//! the evaluations' name: once each reader of the estimates on the viewer's host has
//! acknowledged the last sample, or at once when there is none. The rover then ends
//! as promptly as on one host, and still waits for an evaluation that is there.
//!
//! ```
//! # use dyfos_link::evaluations::Evaluations;
//! # use dyfos_shared::wire::mission::EvaluationAckMsg;
//! let mut e = Evaluations::default();
//! // The last sample, 40, reached two evaluations on this host: nothing to say yet.
//! assert_eq!(e.finished(40, 2), None);
//! assert_eq!(e.acknowledged(EvaluationAckMsg { sample: 40 }), None);
//! // The second one makes it: one acknowledgement goes to the rover's host.
//! assert_eq!(e.acknowledged(EvaluationAckMsg { sample: 40 }), Some(EvaluationAckMsg { sample: 40 }));
//! // With no evaluation here, at once.
//! assert_eq!(e.finished(7, 0), Some(EvaluationAckMsg { sample: 7 }));
//! ```

use dyfos_shared::wire::mission::EvaluationAckMsg;

/// The last sample handed to this host's readers, and how many of them have
/// acknowledged it.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Evaluations {
    last: Option<u64>,
    readers: usize,
    acks: usize,
    answered: bool,
}

impl Evaluations {
    /// The rover's last sample, `sample`, reached `readers` readers on this host.
    /// Returns the acknowledgement to send to the rover's host if there is no one
    /// to wait for.
    pub fn finished(&mut self, sample: u64, readers: usize) -> Option<EvaluationAckMsg> {
        *self = Evaluations { last: Some(sample), readers, acks: 0, answered: false };
        self.answer()
    }

    /// An evaluation on this host acknowledged `ack`. Returns the one
    /// acknowledgement for the rover's host once every reader has (what comes
    /// before the last sample, or after the answer, is not passed on).
    pub fn acknowledged(&mut self, ack: EvaluationAckMsg) -> Option<EvaluationAckMsg> {
        match self.last {
            Some(last) if ack.sample >= last && !self.answered => {
                self.acks += 1;
                self.answer()
            }
            _ => None,
        }
    }

    fn answer(&mut self) -> Option<EvaluationAckMsg> {
        let sample = self.last?;
        if self.answered || self.acks < self.readers {
            return None;
        }
        self.answered = true;
        Some(EvaluationAckMsg { sample })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_acknowledgement_once_every_reader_has_and_nothing_before_the_finish() {
        let mut e = Evaluations::default();
        // An evaluation's acknowledgement with no finish seen: nothing to answer for.
        assert_eq!(e.acknowledged(EvaluationAckMsg { sample: 3 }), None);
        assert_eq!(e.finished(10, 1), None);
        // An older sample does not count.
        assert_eq!(e.acknowledged(EvaluationAckMsg { sample: 9 }), None);
        assert_eq!(e.acknowledged(EvaluationAckMsg { sample: 10 }), Some(EvaluationAckMsg { sample: 10 }));
        // Answered once only.
        assert_eq!(e.acknowledged(EvaluationAckMsg { sample: 10 }), None);
        // A new mission of the same name starts over.
        assert_eq!(e.finished(4, 0), Some(EvaluationAckMsg { sample: 4 }));
        assert_eq!(e.acknowledged(EvaluationAckMsg { sample: 4 }), None);
    }
}
