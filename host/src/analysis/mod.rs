//! Residual analysis ("Closing the loop" in `ARCHITECTURE.md`): fit the base model, compare its
//! residual with the noise floor, test candidate effects by held-out error, refit with those the
//! data support, and report what is left.
//!
//! - the observations (pose and window means with standard errors, temperature, time, force)
//!   are [`crate::pipeline::observations`], which `fit`'s verdict tests too;
//! - [`earth_rate`]: the Earth's rotation removed from the gyroscope's rest readings;
//! - [`noise`]: the floor and the chi-square test;
//! - [`effects`]: the candidate families and their parameters;
//! - [`extended_fit`]: the base model plus effects, fitted jointly;
//! - [`crossval`]: held-out losses by pose and the acceptance rule;
//! - [`time_structure`]: whether a model's residual still follows time;
//! - [`report`]: JSON, text and SVG plots.
//!
//! Selection is forward: every remaining candidate is tested against the current model; the
//! one with the smallest p-value among those that pass is accepted, and the round repeats.
//! `bias_temperature` enters at the degree (1–3) the nested F test of χ² chooses on every
//! observation ([`selection::DEGREE_ALPHA`]), and that degree is chosen again beside each effect
//! accepted after it (a temperature polynomial fitted while another effect was still in the
//! residual can be short of a degree). When no candidate passes alone but the residual is above
//! the floor, the pairs of candidates are tested jointly, with `m` = the number of pairs, and
//! each member must also pass beside the other alone: two real effects can hide each other,
//! each tested against a floor that the other's residual inflates.
//! Temperature and time are told apart on the data: when the winner of a round is a time or
//! temperature effect and its rival (the drift for a temperature effect, the temperature
//! polynomial for a drift) is a candidate too, both are fitted together and the nested F test
//! asks whether each lowers χ² beside the other, against the noise the joint model leaves. The
//! rival alone adding: the rival is taken instead. Neither adding: the two are confounded — the
//! best temperature effect that passes is accepted marked *provisional: confounded with time* —
//! the firmware applies temperature terms only — and its time rival is reported `confounded`;
//! the note names the recording that would confirm it (a cool-down or a second warm-up). A
//! correlation of pose temperature and pose time above [`CONFOUNDING_LIMIT`] in magnitude does
//! not by itself set a drift aside, but a temperature effect is then provisional even when it
//! beats the drift: temperature following time, a polynomial in it is one in time too, and the
//! time family holds only the linear drift. Candidates whose model cannot be fitted on every
//! held-out fold are reported `not_fittable`, with the number of poses still needed. A time or
//! temperature effect must also pass a form check: a bias free in shape over the same variable
//! (constant within each of 8 quantile bins), added to it, must not both fit significantly better
//! (lack-of-fit F test at [`crossval::FORM_ALPHA`]) and predict the held-out poses better by the
//! worth-having gain; otherwise the dependence has another form than the family (a step,
//! hysteresis, a random walk — the check does not say which) and the effect is rejected rather
//! than accepted as an approximation. A temperature effect must pass the same check against a
//! bias free in shape over time (any slow change of the bias is a function of time in a
//! sequential recording). The model the free shape is compared with holds the other time or
//! temperature candidate too, while that one is untested: a true drift beside a true
//! temperature effect is otherwise a slow change in time that the free shape fits and the
//! polynomial cannot. An accepted `bias_drift` is taken out again when
//! the final residual still follows time ([`time_structure`]): a linear trend then is the
//! straight-line part of a random walk, steps or hysteresis, not a drift. When accepted effects
//! leave a residual above the floor the report says "partly explained".

pub mod crossval;
pub mod earth_rate;
pub mod effects;
pub mod extended_fit;
pub mod report;
pub mod result;
pub mod selection;
pub mod sensors;
pub mod time_structure;

pub use result::{
    AnalysisError, AnalysisOptions, CalibrationTerms, Coefficient, EffectResult, EffectStatus,
    RecordingAnalysis, SensorAnalysis,
};
pub use selection::{analyse_observations, SensorSetup, CONFOUNDING_LIMIT};
pub use sensors::{analyse_calibration, analyse_recording, analyse_sensor};
