//! The simulated board: the world and a person moving the board, the sensor physics with its
//! hidden effects, an emulated LSM9DS1 or BMI270 + BMM150 read by the real driver, and the real firmware core
//! ([`imucal_firmware::device::Device`]) with its parameter store on a RAM flash.
//!
//! Every sample period, at simulated time `t`: the person reacts to what the firmware sent, the
//! world gives the true specific force, rate, field and temperature, the physics turns them into
//! the readings `x = A⁻¹·y + b + …` (see [`crate::physics`]), the chip is set to those readings,
//! and the firmware's `poll()` reads the chip through the driver at `t`. The firmware's clock is
//! simulated time. The flash survives [`SimBoard::reboot`], a power cycle that rebuilds the
//! firmware from it as a real reset does; a power cut can be scheduled at any flash step.

mod imu;
mod link;
mod parts;
mod person;

use imucal_firmware::device::{Device, DeviceError, DeviceInfo};
use imucal_firmware::lsm9ds1;
use imucal_firmware::store::{ParamStore, StoreError};
use imucal_protocol::{DeviceId, FirmwareVersion, SensorSet};
use nalgebra::Vector3;
use thiserror::Error;

use crate::effects::EffectRequest;
use crate::error::SimError;
use crate::lsm9ds1_chip::NonFinitePhysicalValue;
use crate::physics::{ImuErrorRanges, ImuPhysics, ImuSample, ImuTruth};
use crate::poser::{build_schedule, PoserOptions, ScheduleKind};
use crate::recording::{SimConfig, Truth, WorldTruth};
use crate::world::{
    EarthField, LocalDisturbance, TemperatureProfile, World, WorldState, STANDARD_GRAVITY_MPS2,
};

pub use imu::{BoardChip, BoardImu, BoardImuError, SensorChip, SharedBmi270, SIM_BMI270_CONFIG};
pub use link::{link_pair, DeviceLink, LinkEnd, LinkObservations, TX_BUFFER_LIMIT};
pub use parts::{
    BoardFlash, SharedChip, SharedFlash, SimClock, FLASH_SECTOR, FLASH_SIZE, FLASH_WORD,
};
pub use person::{Person, PersonPhase, PersonSchedule, Prompts, Screen, CORNER_PATIENCE_S};

/// Size of each of the two parameter slots: one flash sector.
pub const SLOT_SIZE: u32 = FLASH_SECTOR as u32;
/// Firmware version the simulated board reports.
pub const SIM_FIRMWARE_VERSION: FirmwareVersion = FirmwareVersion {
    major: 0,
    minor: 1,
    patch: 0,
};

/// The firmware core as built on the simulated board.
pub type BoardDevice = Device<BoardImu, DeviceLink, SharedFlash, SimClock>;

/// Why the simulated board could not be built or run.
#[derive(Debug, Error)]
pub enum BoardError {
    /// A setting of the world, physics or person is invalid.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The real driver could not configure the emulated chip.
    #[error("the driver could not configure the emulated chip: {0}")]
    Driver(String),
    /// The firmware core refused to start.
    #[error("the firmware core did not start: {0}")]
    Device(String),
    /// The parameter store layout does not fit the simulated flash.
    #[error("the parameter store could not be opened: {0}")]
    Store(StoreError),
    /// The physics produced a value the chip cannot represent.
    #[error(transparent)]
    NonFinite(#[from] NonFinitePhysicalValue),
}

impl From<DeviceError> for BoardError {
    fn from(error: DeviceError) -> Self {
        Self::Device(error.to_string())
    }
}

/// Everything that determines a simulated board.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardConfig {
    /// Seed of every random draw (board errors, effects, noise, the person's positions).
    pub seed: u64,
    /// Effects switched on without telling the host.
    pub effects: Vec<EffectRequest>,
    /// What the person holding the board does.
    pub schedule: PersonSchedule,
    /// How the person moves; `hold_s` is the hold length used to draw positions and to place
    /// bias steps, while holds themselves last until captured (see `max_hold_s`).
    pub poser: PoserOptions,
    /// Longest hold once the host prompts, s, when no capture completes.
    pub max_hold_s: f64,
    /// Ranges the board's errors are drawn from.
    pub error_ranges: ImuErrorRanges,
    /// Magnitude of gravity, m/s².
    pub gravity_mps2: f64,
    /// The Earth's field.
    pub earth_field: EarthField,
    /// Optional local field disturbance.
    pub disturbance: Option<LocalDisturbance>,
    /// A local field, world frame µT, present while the person goes through the positions (the
    /// holds, corners included, and the turns between them) and gone from the tumble on: a
    /// magnetised tool left next to the board during the positions and taken away before the
    /// tumble. The holds and the moves between them then see another field than the one the
    /// magnetometer is calibrated on; `None` by default.
    pub positions_field_ut: Option<[f64; 3]>,
    /// Die temperature over time; `None` keeps the person's ambient temperature.
    pub temperature: Option<TemperatureProfile>,
    /// Configuration the firmware's LSM9DS1 driver applies (its rate is the sample rate).
    pub chip: lsm9ds1::Config,
    /// Which sensor chip the board carries.
    pub sensor: SensorChip,
    /// LSM9DS1 conversion timing: `Some(e)` makes the chip convert on its own oscillator at
    /// `1 + e` times the nominal rates (e.g. ±0.005), with data-ready flags, so reads repeat or
    /// miss conversions as the clocks drift and the 80 Hz magnetometer repeats under 119 Hz
    /// reads; `None` gives a new value of every sensor at every read.
    pub lsm9ds1_odr_error: Option<f64>,
    /// Unique id the board reports.
    pub device_id: u64,
    /// A hardware fault of this board (none by default).
    pub fault: Option<crate::faults::HardwareFault>,
}

impl BoardConfig {
    /// Defaults: guided person, consumer MEMS errors, no effects, standard gravity, 48 µT at
    /// 60° dip, 25 °C, the driver's default configuration (119 Hz), holds of at most 20 s.
    pub fn new(seed: u64) -> Self {
        Self {
            seed,
            effects: Vec::new(),
            schedule: PersonSchedule::Guided,
            poser: PoserOptions::default(),
            max_hold_s: 20.0,
            error_ranges: ImuErrorRanges::default(),
            gravity_mps2: STANDARD_GRAVITY_MPS2,
            earth_field: EarthField::default(),
            disturbance: None,
            positions_field_ut: None,
            temperature: None,
            chip: lsm9ds1::Config::default(),
            sensor: SensorChip::Lsm9ds1,
            lsm9ds1_odr_error: None,
            device_id: 0x5349_4d00_0000_0000 | (seed & 0xFFFF_FFFF),
            fault: None,
        }
    }

    /// Scales of the configured chip (its rate is the sample rate).
    pub fn scales(&self) -> imucal_protocol::SensorScales {
        match self.sensor {
            SensorChip::Lsm9ds1 => self.chip.scales(),
            SensorChip::Bmi270 => imucal_firmware::bmi270::scales(),
        }
    }
}

/// The simulated board (see the module documentation).
pub struct SimBoard {
    config: BoardConfig,
    world: World,
    physics: ImuPhysics,
    person: Person,
    chip: BoardChip,
    flash: SharedFlash,
    clock: SimClock,
    link: LinkEnd,
    /// `None` only transiently during a reboot.
    device: Option<BoardDevice>,
    powered: bool,
    period_us: u64,
    next_sample_us: u64,
    samples: u64,
    last_sample: Option<ImuSample>,
    last_state: Option<WorldState>,
    expected_duration_s: f64,
    /// What the host's screen shows the person.
    screen: Screen,
}

impl std::fmt::Debug for SimBoard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimBoard")
            .field("seed", &self.config.seed)
            .field("time_us", &self.clock.get_us())
            .field("samples", &self.samples)
            .field("powered", &self.powered)
            .field("phase", &self.person.phase())
            .finish_non_exhaustive()
    }
}

impl SimBoard {
    /// Build the board at simulated time 0 with an erased flash and boot the firmware.
    pub fn new(config: BoardConfig) -> Result<Self, BoardError> {
        let rate = f64::from(config.scales().sample_rate_hz);
        let person = Person::new(
            config.schedule,
            &config.poser,
            config.max_hold_s,
            &config.earth_field,
            config.seed,
        )?;
        let temperature = config.temperature.unwrap_or(TemperatureProfile::Constant {
            temp_c: config.poser.ambient_c,
        });
        let plan = build_schedule(
            ScheduleKind::Twelve,
            &config.poser,
            &config.earth_field,
            config.seed,
        )?;
        let world = World {
            trajectory: plan.trajectory,
            gravity_mps2: config.gravity_mps2,
            earth_field: config.earth_field,
            disturbance: config.disturbance,
            temperature,
        };
        world.validate()?;
        for v in config.positions_field_ut.into_iter().flatten() {
            crate::error::require_finite("field during the positions (µT)", v)?;
        }
        // Bias steps are placed within the session a person would take: positions and tumble.
        let tumble = build_schedule(
            ScheduleKind::Tumble,
            &config.poser,
            &config.earth_field,
            config.seed,
        )?;
        let expected_duration_s = world.trajectory.duration_s() + tumble.trajectory.duration_s();
        let mut truth = ImuTruth::draw(
            config.seed,
            &config.error_ranges,
            &config.effects,
            rate,
            expected_duration_s,
        )?;
        if let Some(fault) = &config.fault {
            fault.apply(&mut truth);
        }
        let physics = ImuPhysics::new(truth, config.seed)?;
        let (device_link, link) = link_pair();
        let mut board = Self {
            world,
            physics,
            person,
            chip: BoardChip::new(config.sensor, config.lsm9ds1_odr_error),
            flash: SharedFlash::new(),
            clock: SimClock::default(),
            link,
            device: None,
            powered: true,
            period_us: 1,
            next_sample_us: 0,
            samples: 0,
            last_sample: None,
            last_state: None,
            expected_duration_s,
            screen: Screen::Unknown,
            config,
        };
        board.boot(device_link)?;
        Ok(board)
    }

    /// Power up: a fresh chip configured by the real driver, the store opened from the flash,
    /// and the firmware core built on them.
    fn boot(&mut self, link: DeviceLink) -> Result<(), BoardError> {
        self.chip.power_cycle();
        let driver = self
            .chip
            .driver(self.config.chip)
            .map_err(|e| BoardError::Driver(e.to_string()))?;
        self.flash.with(|flash| flash.restore_power());
        let store = ParamStore::new(self.flash.clone(), 0, SLOT_SIZE).map_err(BoardError::Store)?;
        let info = DeviceInfo {
            device_id: DeviceId::from_u64(self.config.device_id),
            firmware_version: SIM_FIRMWARE_VERSION,
            sensors: SensorSet {
                accel: true,
                gyro: true,
                mag: true,
                temp: true,
            },
        };
        let device = Device::new(driver, link, store, self.clock.clone(), info)?;
        // The firmware samples every `period_us` from its boot time; keep to the same grid so
        // that each sample is taken exactly when the world was evaluated.
        let rate = f64::from(self.config.scales().sample_rate_hz);
        self.period_us = ((1.0e6 / rate) + 0.5) as u64;
        self.next_sample_us = self.clock.get_us();
        self.device = Some(device);
        self.powered = true;
        Ok(())
    }

    /// Power-cycle the board: the firmware restarts from the flash, bytes the firmware had not
    /// yet read are lost, the chip is reset and configured again. Also restores power after a cut.
    pub fn reboot(&mut self) -> Result<(), BoardError> {
        let link = match self.device.take() {
            Some(device) => {
                let (_driver, link, _store, _clock) = device.into_parts();
                link
            }
            None => {
                // Only reachable if a previous boot failed: start with a fresh link.
                let (device_link, end) = link_pair();
                self.link = end;
                device_link
            }
        };
        self.link.reset_receiver();
        self.boot(link)
    }

    /// Cut the power during flash step `step` (sector erases and words written, counted from
    /// now); the board then stays dead until [`Self::reboot`]. `None` cancels.
    pub fn cut_power_at_flash_step(&mut self, step: Option<u32>) {
        self.flash.with(|flash| {
            let offset = flash.steps();
            flash.cut_power_at_step(step.map(|s| s.saturating_add(offset)));
        });
    }

    /// Whether the board is running (false after a power cut, until a reboot).
    pub fn is_powered(&self) -> bool {
        self.powered
    }

    /// Flash steps done since the last power-up.
    pub fn flash_steps(&self) -> u32 {
        self.flash.with(|flash| flash.steps())
    }

    /// The host's end of the serial link.
    pub fn link(&self) -> &LinkEnd {
        &self.link
    }

    /// Simulated time, µs.
    pub fn time_us(&self) -> u64 {
        self.clock.get_us()
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.clock.get_us() as f64 * 1e-6
    }

    /// Sample period of the firmware, µs.
    pub fn sample_period_us(&self) -> u64 {
        self.period_us
    }

    /// Time of the next sample, µs.
    pub fn next_sample_us(&self) -> u64 {
        self.next_sample_us
    }

    /// Samples taken since the board was built.
    pub fn samples_taken(&self) -> u64 {
        self.samples
    }

    /// The person holding the board.
    pub fn person(&self) -> &Person {
        &self.person
    }

    /// Show the person what the host's screen asks for (see [`Screen`]); they react from the
    /// next sample on.
    pub fn show(&mut self, screen: Screen) {
        self.screen = screen;
    }

    /// Tell the person which positions a resumed session already holds (body-frame up
    /// directions): they skip them, as a person reading the host's list would.
    pub fn tell_held(&mut self, ups: &[[f64; 3]]) {
        self.person.skip_held(ups);
    }

    /// The configuration the board was built from.
    pub fn config(&self) -> &BoardConfig {
        &self.config
    }

    /// The world's true state at the latest sample.
    pub fn last_world_state(&self) -> Option<&WorldState> {
        self.last_state.as_ref()
    }

    /// The physics' output at the latest sample (what the chip was set to).
    pub fn last_sample(&self) -> Option<&ImuSample> {
        self.last_sample.as_ref()
    }

    /// The firmware core, while powered.
    pub fn device(&self) -> Option<&BoardDevice> {
        self.device.as_ref().filter(|_| self.powered)
    }

    /// Every true parameter of the board; `duration_s` is the simulated time so far.
    pub fn truth(&self) -> Truth {
        let mut poser = self.config.poser;
        poser.tremor &= self.config.schedule == PersonSchedule::Guided;
        Truth {
            config: SimConfig {
                seed: self.config.seed,
                schedule: ScheduleKind::Twelve,
                poser,
                sample_rate_hz: self.physics.truth().sample_rate_hz,
                gravity_mps2: self.world.gravity_mps2,
                earth_field: self.world.earth_field,
                disturbance: self.world.disturbance,
                temperature: Some(self.world.temperature),
                error_ranges: self.config.error_ranges,
                effects: self.config.effects.clone(),
            },
            world: WorldTruth {
                gravity_mps2: self.world.gravity_mps2,
                earth_field: self.world.earth_field,
                field_world_ut: self.world.earth_field.world_vector_ut().into(),
                disturbance: self.world.disturbance,
                temperature: self.world.temperature,
            },
            imu: *self.physics.truth(),
            duration_s: self.time_s(),
        }
    }

    /// Session length the effects were drawn for (bias steps fall inside it), s.
    pub fn expected_duration_s(&self) -> f64 {
        self.expected_duration_s
    }

    /// The field of [`BoardConfig::positions_field_ut`] now, world frame µT (zero once the
    /// person has left the positions).
    fn positions_field(&self) -> Vector3<f64> {
        match (self.config.positions_field_ut, self.person.phase()) {
            (Some(field), PersonPhase::Hold { .. } | PersonPhase::TurnToHold { .. }) => {
                Vector3::from(field)
            }
            _ => Vector3::zeros(),
        }
    }

    /// The true state of the world at `t_s` with the person's current motion.
    fn world_state(&self, t_s: f64) -> WorldState {
        let motion = self.person.motion_at(t_s);
        let to_body = motion.q_body_to_world.inverse();
        WorldState {
            t: t_s,
            q_body_to_world: motion.q_body_to_world,
            omega_body: motion.omega_body,
            specific_force_body: to_body * (-self.world.gravity_world()),
            field_body: to_body * (self.world.field_world_at(t_s) + self.positions_field()),
            temp_c: self.world.temperature.at(t_s),
        }
    }

    /// Run the board up to simulated time `t_us`: every sample due on the way, then one more turn
    /// of the firmware's main loop at `t_us` (to answer what arrived since the last sample).
    pub fn advance_to(&mut self, t_us: u64) -> Result<(), BoardError> {
        while self.next_sample_us <= t_us {
            let t = self.next_sample_us;
            self.sample_at(t)?;
            self.next_sample_us = t.saturating_add(self.period_us);
        }
        if t_us > self.clock.get_us() {
            self.clock.set_us(t_us);
            self.poll();
        }
        Ok(())
    }

    /// Run the board for `seconds` of simulated time.
    pub fn run_for(&mut self, seconds: f64) -> Result<(), BoardError> {
        let step = crate::error::require_non_negative("run time (s)", seconds)?;
        let target = self.time_us().saturating_add((step * 1e6).round() as u64);
        self.advance_to(target)
    }

    fn sample_at(&mut self, t_us: u64) -> Result<(), BoardError> {
        let t_s = t_us as f64 * 1e-6;
        let observed = self.link.observations();
        self.person.observe(
            t_s,
            Prompts {
                capture_requests: observed.capture_requests,
                poses_captured: observed.poses_captured,
                stream_starts: observed.stream_starts,
                stream_stops: observed.stream_stops,
                streaming: observed.streaming,
                screen: self.screen,
            },
        )?;
        let state = self.world_state(t_s);
        let sample = self.physics.sample(&state);
        let v = |x: Vector3<f64>| [x.x, x.y, x.z];
        self.chip.set_physical(
            v(sample.accel.analog),
            v(sample.gyro.analog),
            v(sample.mag.analog),
            state.temp_c,
        )?;
        self.chip.set_time(t_s);
        self.clock.set_us(t_us);
        self.samples += 1;
        self.last_sample = Some(sample);
        self.last_state = Some(state);
        self.poll();
        Ok(())
    }

    /// One turn of the firmware's main loop, if powered. Bytes sent during a turn in which the
    /// power failed never left the board and are dropped.
    fn poll(&mut self) {
        if !self.powered {
            return;
        }
        let Some(device) = self.device.as_mut() else {
            return;
        };
        let before = self.link.pending_from_device();
        device.poll();
        if !self.flash.with(|flash| flash.is_powered()) {
            self.powered = false;
            self.link.truncate_from_device(before);
        }
    }
}
