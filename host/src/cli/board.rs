//! The board a command talks to: which protocol it runs, how its port is chosen (or a
//! simulated board started behind it), the client connection, and a one-line description of
//! the set it holds. `--sim` starts a simulated board in-process behind a pseudo-terminal, in
//! real time, running imucal's firmware or Adafruit's MotionCal sketch from a fresh store, which
//! the command then opens with the same serial-port code as hardware. Shared by the board commands (`device.rs`, `device_stream.rs`,
//! `params.rs`) and `calibrate`.

use std::time::{SystemTime, UNIX_EPOCH};

use clap::Args;
use imucal::device::{choose_port, list_ports, DeviceClient};
use imucal_protocol::CalibrationSet;

/// What a board runs, so which protocol talks to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum BoardProtocol {
    /// imucal's firmware (binary frames, poses averaged on the board).
    #[default]
    Imucal,
    /// A sketch for PJRC's MotionCal (`Raw:`/`Uni:` lines, the 68-byte calibration packet).
    Motioncal,
}

/// Which port to use.
#[derive(Debug, Args)]
pub struct PortArgs {
    /// Serial port, e.g. /dev/ttyACM0, COM3, or a pseudo-terminal of the simulator (default:
    /// the only likely board from `imucal ports`).
    #[arg(long, short = 'p', conflicts_with = "sim")]
    pub port: Option<String>,
    /// Use a simulated board started in-process (real time, identity parameters at start).
    #[arg(long)]
    pub sim: bool,
    /// Simulator: seed of the board's sensor errors, noise and device id.
    #[arg(long, default_value_t = 1, requires = "sim", value_parser = super::values::whole_number::<u64>)]
    pub sim_seed: u64,
}

/// The serial port a command opens, and with `--sim` the simulated board serving it, which
/// lives as long as this value.
pub struct BoardPort {
    /// The port's path.
    pub path: String,
    _sim: Option<SimBoard>,
}

impl PortArgs {
    /// The port given, the simulated board's (running `protocol`), or the only likely board
    /// (announced on stderr).
    pub(super) fn open_board(&self, protocol: BoardProtocol) -> anyhow::Result<BoardPort> {
        if self.sim {
            let sim = SimBoard::start(self.sim_seed, protocol)?;
            return Ok(BoardPort {
                path: sim.port(),
                _sim: Some(sim),
            });
        }
        let path = given_or_only_board(self.port.as_deref())?;
        Ok(BoardPort { path, _sim: None })
    }
}

/// The port given, or else the only likely board (announced on stderr).
pub(super) fn given_or_only_board(port: Option<&str>) -> anyhow::Result<String> {
    Ok(match port {
        Some(port) => port.to_string(),
        None => {
            let chosen = choose_port(&list_ports()?)?.path.clone();
            say!("using port {chosen}");
            chosen
        }
    })
}

/// A client of the board running imucal's firmware at `args`; keep the [`BoardPort`] while
/// the client is in use.
pub(super) fn connect(args: &PortArgs) -> anyhow::Result<(DeviceClient, BoardPort)> {
    let board = args.open_board(BoardProtocol::Imucal)?;
    Ok((DeviceClient::open(&board.path)?, board))
}

/// One line on the set a board holds: identity, or its age and fit residuals.
pub(super) fn describe_params(set: &CalibrationSet) -> String {
    let identity = CalibrationSet::identity();
    if set.accel == identity.accel && set.gyro == identity.gyro && set.mag == identity.mag {
        return "identity (uncalibrated)".to_string();
    }
    let age = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|now| now.as_secs().saturating_sub(set.created_unix_s))
        .unwrap_or(0);
    let r = set.residuals;
    format!(
        "calibrated {} days ago; fit residual RMS accel {} m/s², gyro {} rad/s, mag {} µT",
        age / 86_400,
        r.accel_rms,
        r.gyro_rms,
        r.mag_rms
    )
}

/// A simulated board serving a pseudo-terminal until it is dropped (boxed: both handles
/// carry the board's truth).
#[cfg(feature = "sim")]
pub(super) enum SimBoard {
    /// imucal's firmware on the simulated Nano 33 BLE Sense.
    Firmware(Box<imucal_hil_sim::serve::SimHandle>),
    /// Adafruit's calibration sketch.
    Sketch(Box<imucal_hil_sim::motioncal_serve::MotionCalHandle>),
}

#[cfg(feature = "sim")]
impl SimBoard {
    /// Starts the board that runs `protocol`, its sensor errors drawn from `seed`.
    pub(super) fn start(seed: u64, protocol: BoardProtocol) -> anyhow::Result<Self> {
        use anyhow::Context;
        use imucal_hil_sim::motioncal_serve::MotionCalHandle;
        use imucal_hil_sim::serve::{SimOptions, SimServer};
        let board = match protocol {
            BoardProtocol::Imucal => {
                SimServer::start(SimOptions::new(seed)).map(|h| Self::Firmware(Box::new(h)))
            }
            BoardProtocol::Motioncal => {
                MotionCalHandle::start(seed, 1.0).map(|h| Self::Sketch(Box::new(h)))
            }
        };
        let board = board.context("the simulated board could not start")?;
        say!(
            "Simulated board running {} (seed {seed}, real time) on {}",
            match protocol {
                BoardProtocol::Imucal => "imucal's firmware",
                BoardProtocol::Motioncal => "Adafruit's MotionCal calibration sketch",
            },
            board.port()
        );
        Ok(board)
    }

    /// The pseudo-terminal to open.
    pub(super) fn port(&self) -> String {
        match self {
            Self::Firmware(handle) => handle.port_path().to_string(),
            Self::Sketch(handle) => handle.port_path().to_string(),
        }
    }
}

/// Without the simulator there is no simulated board (`start` explains).
#[cfg(not(feature = "sim"))]
pub(super) enum SimBoard {}

#[cfg(not(feature = "sim"))]
impl SimBoard {
    pub(super) fn start(_seed: u64, _protocol: BoardProtocol) -> anyhow::Result<Self> {
        anyhow::bail!(
            "this imucal was built without the simulator; rebuild with the default features \
             (cargo build -p imucal) to use --sim, or give --port"
        )
    }

    pub(super) fn port(&self) -> String {
        match *self {}
    }
}
