//! The farm protocol's meanings, in one place: how a worker says it cannot
//! take a task (a typed `TaskRefusal` in the gRPC status's details for a
//! pause and for missing optics; status codes for refusals and failures),
//! and what the
//! coordinator makes of a status. Neither side reads meaning into a
//! status's text.

use super::proto::{self, Missing, WorkerState};
use tonic::Status;

/// How a task ended badly.
#[derive(Debug)]
pub(crate) enum TaskError {
    /// The worker is paused: re-queue, no blame.
    Paused(String),
    /// Another runner won, or the render stops.
    Cancelled,
    /// A failure that counts against the worker.
    Failed(String),
    /// The worker refuses this job (versions, token): quarantine at once.
    Refused(String),
    /// The worker does not hold the optics the task names: send them.
    OpticsMissing,
}

/// The status a paused worker answers a task with: UNAVAILABLE, with a
/// [`proto::TaskRefusal`] in its details saying so and why.
pub fn paused_status(reason: &str) -> Status {
    use prost::Message;
    let refusal = proto::TaskRefusal {
        state: WorkerState::Paused as i32,
        paused_reason: reason.to_string(),
        ..Default::default()
    };
    Status::with_details(tonic::Code::Unavailable, format!("paused ({reason})"), refusal.encode_to_vec().into())
}

/// The status a worker answers a task naming optics it does not hold (and
/// not carrying them) with: NOT_FOUND, with a [`proto::TaskRefusal`]
/// saying MISSING_OPTICS in its details.
pub fn optics_missing_status(optics_hash: &str) -> Status {
    use prost::Message;
    let refusal = proto::TaskRefusal { missing: Missing::Optics as i32, ..Default::default() };
    Status::with_details(
        tonic::Code::NotFound,
        format!("optics {optics_hash} are not held by this worker; send them with the task"),
        refusal.encode_to_vec().into(),
    )
}

/// What a gRPC status means for the task. A paused worker says so in the
/// status's details (a typed `TaskRefusal`), not in its text.
pub(crate) fn classify(status: &tonic::Status) -> TaskError {
    use prost::Message;
    use tonic::Code;
    let msg = status.message().to_string();
    if let Ok(r) = proto::TaskRefusal::decode(status.details()) {
        if r.state == WorkerState::Paused as i32 {
            return TaskError::Paused(r.paused_reason);
        }
        if r.missing == Missing::Optics as i32 && status.code() == Code::NotFound {
            return TaskError::OpticsMissing;
        }
    }
    match status.code() {
        Code::Unauthenticated => TaskError::Refused(format!("refused the token: {msg}")),
        Code::FailedPrecondition => TaskError::Refused(msg),
        Code::Cancelled => TaskError::Failed(format!("cancelled by the worker: {msg}")),
        code => TaskError::Failed(format!("{code:?}: {msg}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_paused_worker_is_recognised_by_its_typed_refusal_not_its_text() {
        match classify(&paused_status("schedule")) {
            TaskError::Paused(reason) => assert_eq!(reason, "schedule"),
            other => panic!("{other:?}"),
        }
        // The same words without the typed refusal are a plain failure.
        assert!(matches!(classify(&Status::unavailable("paused (schedule)")), TaskError::Failed(_)));
        assert!(matches!(classify(&Status::unauthenticated("no")), TaskError::Refused(_)));
    }

    #[test]
    fn missing_optics_are_a_typed_not_found() {
        assert!(matches!(classify(&optics_missing_status("abc")), TaskError::OpticsMissing));
        // A NOT_FOUND without the typed refusal (another service, a proxy)
        // is a failure, not a request for the optics.
        assert!(matches!(classify(&Status::not_found("optics abc are not held")), TaskError::Failed(_)));
    }
}
