//! Why a progressive render stopped ([`StopReason`]), written in statistics and results files
//! as the sentence its `Display` prints.

use std::borrow::Cow;
use std::fmt;

use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use serde::{Deserialize, Serialize};

/// Why the progressive loop stopped. Serialized as its sentence (`converged: no brick
/// requested`, `time budget spent`, ...), which it is read back from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(into = "String", try_from = "String")]
pub enum StopReason {
    /// A frame requested no brick (beyond bricks that failed).
    Converged,
    /// The time budget ran out.
    TimeBudget,
    /// Bricks were wanted but no cache slot could be freed for them.
    CacheFull,
    /// Every frame of the frame budget was rendered.
    FrameBudget {
        /// The frame budget.
        max_frames: u32,
    },
}

/// The sentences of the reasons without a number, by variant.
const CONVERGED: &str = "converged: no brick requested";
const TIME_BUDGET: &str = "time budget spent";
const CACHE_FULL: &str = "cache full: every slot holds a brick the current view uses";
/// The sentence of [`StopReason::FrameBudget`] is `FRAME_BUDGET.0 N FRAME_BUDGET.1`.
const FRAME_BUDGET: (&str, &str) = ("frame budget of ", " frames spent");

impl fmt::Display for StopReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Converged => f.write_str(CONVERGED),
            Self::TimeBudget => f.write_str(TIME_BUDGET),
            Self::CacheFull => f.write_str(CACHE_FULL),
            Self::FrameBudget { max_frames } => {
                write!(f, "{}{max_frames}{}", FRAME_BUDGET.0, FRAME_BUDGET.1)
            }
        }
    }
}

/// A text that is no [`StopReason`]'s sentence.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown stop reason '{text}'")]
pub struct UnknownStopReason {
    /// The text given.
    pub text: String,
}

impl std::str::FromStr for StopReason {
    type Err = UnknownStopReason;

    fn from_str(s: &str) -> Result<Self, UnknownStopReason> {
        let frames = s
            .strip_prefix(FRAME_BUDGET.0)
            .and_then(|rest| rest.strip_suffix(FRAME_BUDGET.1))
            .filter(|n| n.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|n| n.parse().ok());
        match (s, frames) {
            (CONVERGED, _) => Ok(Self::Converged),
            (TIME_BUDGET, _) => Ok(Self::TimeBudget),
            (CACHE_FULL, _) => Ok(Self::CacheFull),
            (_, Some(max_frames)) => Ok(Self::FrameBudget { max_frames }),
            _ => Err(UnknownStopReason {
                text: s.to_string(),
            }),
        }
    }
}

impl From<StopReason> for String {
    fn from(reason: StopReason) -> Self {
        reason.to_string()
    }
}

impl TryFrom<String> for StopReason {
    type Error = UnknownStopReason;

    fn try_from(text: String) -> Result<Self, UnknownStopReason> {
        text.parse()
    }
}

impl JsonSchema for StopReason {
    fn inline_schema() -> bool {
        true
    }

    fn schema_name() -> Cow<'static, str> {
        "StopReason".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "string",
            "anyOf": [
                {"const": CONVERGED},
                {"const": TIME_BUDGET},
                {"const": CACHE_FULL},
                {"pattern": format!("^{}[0-9]+{}$", FRAME_BUDGET.0, FRAME_BUDGET.1)}
            ]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::StopReason;

    #[test]
    fn each_reason_is_written_and_read_as_its_sentence() {
        for (reason, text) in [
            (StopReason::Converged, "converged: no brick requested"),
            (StopReason::TimeBudget, "time budget spent"),
            (
                StopReason::CacheFull,
                "cache full: every slot holds a brick the current view uses",
            ),
            (
                StopReason::FrameBudget { max_frames: 64 },
                "frame budget of 64 frames spent",
            ),
        ] {
            assert_eq!(reason.to_string(), text);
            assert_eq!(serde_json::to_value(reason).unwrap(), text);
            assert_eq!(
                serde_json::from_value::<StopReason>(text.into()).unwrap(),
                reason
            );
        }
        assert_eq!(
            serde_json::from_str::<StopReason>(r#""frame budget of -1 frames spent""#)
                .unwrap_err()
                .to_string(),
            "unknown stop reason 'frame budget of -1 frames spent'"
        );
    }
}
