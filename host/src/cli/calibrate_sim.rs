//! `imucal calibrate --sim`: the simulated board started in-process behind a pseudo-terminal,
//! with its temperature profile; a stub without the `sim` feature.

#[cfg(feature = "sim")]
use anyhow::Context;

use super::args::CalibrateArgs;
#[cfg(feature = "sim")]
use super::args::SimTemperature;

#[cfg(feature = "sim")]
pub(super) fn temperature_profile(
    temperature: SimTemperature,
) -> Option<imucal_hil_sim::world::TemperatureProfile> {
    use imucal_hil_sim::world::TemperatureProfile;
    match temperature {
        SimTemperature::Constant => None,
        SimTemperature::Sweep {
            low_c,
            high_c,
            period_s,
        } => Some(TemperatureProfile::Sweep {
            low_c,
            high_c,
            period_s,
        }),
    }
}

/// The simulated board of `--sim`.
#[cfg(feature = "sim")]
pub(super) struct Simulated {
    handle: imucal_hil_sim::serve::SimHandle,
    fault: Option<imucal_hil_sim::faults::HardwareFault>,
}

#[cfg(feature = "sim")]
impl Simulated {
    pub(super) fn start(args: &CalibrateArgs) -> anyhow::Result<Self> {
        Self::start_board(args, args.sim_seed, None)
    }

    /// A board of a simulated batch: its own seed (errors, noise, device id) and, with
    /// `fault: Some(i)`, the `i`-th realistic hardware fault.
    pub(super) fn start_board(
        args: &CalibrateArgs,
        seed: u64,
        fault: Option<usize>,
    ) -> anyhow::Result<Self> {
        use imucal_hil_sim::faults::HardwareFault;
        use imucal_hil_sim::serve::{SimOptions, SimServer};
        let mut options = SimOptions::new(seed);
        let fault = fault.map(HardwareFault::realistic);
        options.board.fault = fault;
        options.speed = args.speed;
        options.board.sensor = args.sim_chip;
        if let Some(error) = args.sim_odr_error {
            if !(error.is_finite() && error.abs() < 0.5) {
                return Err(super::UsageError(format!(
                    "--sim-odr-error {error} is not a plausible rate error; give a fraction such \
                     as -0.005 (0.5 % slow)"
                ))
                .into());
            }
            options.board.lsm9ds1_odr_error = Some(error);
        }
        options.board.temperature = temperature_profile(args.sim_temperature);
        if args.rounds > 1 {
            options.schedule = imucal_hil_sim::board::PersonSchedule::Rounds(args.rounds);
        }
        options.effects = args
            .sim_effects
            .iter()
            .map(|text| text.parse())
            .collect::<Result<_, _>>()
            .map_err(|e| super::UsageError(format!("a --sim-effect is not understood: {e}")))?;
        let handle = SimServer::start(options).context("the simulated board could not start")?;
        Ok(Self { handle, fault })
    }

    /// The board's hardware fault in words, if it has one.
    pub(super) fn fault_text(&self) -> Option<String> {
        self.fault.map(|f| f.describe())
    }

    pub(super) fn port(&self) -> String {
        self.handle.port_path().to_string()
    }

    /// Show the simulated person what the screen asks for after `event` (see
    /// [`imucal::session::sim_screen`]).
    pub(super) fn show(&self, event: &imucal::session::SessionEvent<'_>) {
        if let Some(screen) = imucal::session::sim_screen::screen_of(event) {
            self.handle.show(screen);
        }
    }

    /// Tell the simulated person which positions a resumed session holds, as a person reads
    /// the list the host prints when it resumes: they skip them.
    pub(super) fn resumed(&self, poses: &[imucal::session::CapturedPose]) {
        let ups = poses
            .iter()
            .map(|p| [p.target.up.x, p.target.up.y, p.target.up.z])
            .collect();
        self.handle.tell_held(ups);
    }

    /// The simulated site's field, µT: it stands for a value looked up for the location.
    pub(super) fn field_ut(&self) -> f64 {
        let field = self.handle.truth().world.field_world_ut;
        field.iter().map(|v| v * v).sum::<f64>().sqrt()
    }

    pub(super) fn save_truth(&self, path: &std::path::Path) -> anyhow::Result<()> {
        imucal_hil_sim::recording::write_truth_file(&self.handle.truth(), path)
            .context("the simulator's truth could not be saved")
    }
}

/// Without the simulator there is no simulated board (`start` explains).
#[cfg(not(feature = "sim"))]
pub(super) enum Simulated {}

#[cfg(not(feature = "sim"))]
impl Simulated {
    pub(super) fn start(args: &CalibrateArgs) -> anyhow::Result<Self> {
        Self::start_board(args, 0, None)
    }

    pub(super) fn start_board(
        _args: &CalibrateArgs,
        _seed: u64,
        _fault: Option<usize>,
    ) -> anyhow::Result<Self> {
        anyhow::bail!(
            "this imucal was built without the simulator; rebuild with the default features \
             (cargo build -p imucal) to use --sim or --sim-boards, or give --port"
        )
    }

    pub(super) fn fault_text(&self) -> Option<String> {
        match *self {}
    }

    pub(super) fn port(&self) -> String {
        match *self {}
    }

    pub(super) fn show(&self, _event: &imucal::session::SessionEvent<'_>) {
        match *self {}
    }

    pub(super) fn resumed(&self, _poses: &[imucal::session::CapturedPose]) {
        match *self {}
    }

    pub(super) fn field_ut(&self) -> f64 {
        match *self {}
    }

    pub(super) fn save_truth(&self, _path: &std::path::Path) -> anyhow::Result<()> {
        match *self {}
    }
}
