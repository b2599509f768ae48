//! The magnetometer phase: the board is turned until every direction region of the field holds
//! enough samples ([`super::coverage`]), or until most are and the field fit expects an `|m|`
//! error within its target. The samples streamed while moving between the positions count, so
//! this phase only fills in the directions they left empty.

use std::io::{Read, Write};
use std::time::Instant;

use super::coverage::{self, Coverage, REGIONS};
use super::error::SessionError;
use super::events::{Phase, SessionEvent};
use super::mag_guidance::Attitude;
use super::runner::Runner;
use super::solve;
use crate::fit::Vec3;

impl<L: Read + Write> Runner<'_, L> {
    /// Whether the turning can stop before every region is covered: at least `floor` regions
    /// are (the coverage accepted at the time limit, so that each empty region borders sampled
    /// ones and the fit does not rest on its covariance alone, which assumes independent noise
    /// and a right model), and the fit of `points` expects an `|m|` error within the quarter
    /// of the budget the verdict asks for ([`solve::expected_mag_error_pct`]).
    fn fit_suffices(&mut self, covered: usize, floor: usize, points: &[Vec3]) -> bool {
        if covered < floor {
            return false;
        }
        let target_pct = self.options.budgets.mag_pct / 4.0;
        let expected = solve::expected_mag_error_pct(
            points,
            self.options.field_ut,
            self.options.mag_max_fit_samples,
        );
        if expected > target_pct {
            return false;
        }
        self.observer.event(&SessionEvent::Note(format!(
            "{covered} of {REGIONS} field directions give an expected |m| error of \
             {expected:.3} % (1σ), within the {target_pct:.3} % target (a quarter of the \
             budget); the turning can stop"
        )));
        true
    }

    pub(super) fn magnetometer(&mut self) -> Result<Coverage, SessionError> {
        self.observer.event(&SessionEvent::MagPrompt);
        self.start_watching()?;
        let start = Instant::now();
        // Directions seen while moving between the positions count as well: the tumble only
        // fills in what they left empty.
        let mut last_update = 0;
        let mut attitude = Attitude::default();
        let regions = REGIONS;
        let needed_at_timeout = (self.options.mag_accept_fraction * regions as f64).ceil() as usize;
        loop {
            let chunk = self.read_chunk()?;
            for sample in &chunk.samples {
                self.record_mag(sample, Phase::Tumble);
                attitude.push(sample);
            }
            let count = self.mag.len();
            let timed_out = start.elapsed() > self.options.mag_timeout;
            if self.mag.len() - last_update < 100 && !timed_out {
                continue;
            }
            last_update = self.mag.len();
            let all: Vec<Vec3> = self.mag.iter().map(|m| Vec3::from(m.mag)).collect();
            let Some(centre) = coverage::sphere_centre(&all) else {
                if timed_out {
                    return Err(SessionError::MagCoverage {
                        waited_s: start.elapsed().as_secs_f64(),
                        covered: 0,
                        needed: needed_at_timeout,
                        regions,
                        empty: "all".into(),
                    });
                }
                continue;
            };
            let cover = Coverage::of(&all, &centre);
            let covered = cover.covered(self.options.mag_min_per_region);
            let empty = cover.empty_regions(self.options.mag_min_per_region);
            self.observer.event(&SessionEvent::MagCoverage {
                covered,
                regions,
                samples: count,
                empty: empty.clone(),
                guidance: attitude.guidance(&cover, self.options.mag_min_per_region),
            });
            if count >= self.options.mag_min_samples
                && (covered == regions || self.fit_suffices(covered, needed_at_timeout, &all))
            {
                self.client.stop_stream()?;
                return Ok(cover);
            }
            if timed_out {
                self.client.stop_stream()?;
                if covered >= needed_at_timeout && count >= self.options.mag_min_samples {
                    self.observer.event(&SessionEvent::Note(format!(
                        "the magnetometer phase ended at its time limit with {covered} of \
                         {regions} directions covered (empty: {}); the fit goes on with them",
                        empty.join(", ")
                    )));
                    return Ok(cover);
                }
                return Err(SessionError::MagCoverage {
                    waited_s: start.elapsed().as_secs_f64(),
                    covered,
                    needed: needed_at_timeout,
                    regions,
                    empty: empty.join(", "),
                });
            }
        }
    }
}
