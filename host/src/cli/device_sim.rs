//! `--sim` of the board commands (`info`, `flash`, `stream`, `record`, `params`): a simulated
//! board started in-process behind a pseudo-terminal, in real time, which the command then opens
//! with the same serial-port code as hardware. It runs imucal's firmware or Adafruit's MotionCal
//! calibration sketch, starts from a fresh store (identity parameters) and ends with the command.

use super::args::BoardProtocol;

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
        eprintln!(
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
