//! Boards that run someone else's firmware: the text lines and the calibration packet of PJRC's
//! MotionCal and the calibration that Adafruit's `Adafruit_Sensor_Calibration` library stores and
//! applies.
//!
//! - [`motioncal`]: the `Raw:`/`Uni:`/`Cal1:`/`Cal2:` lines, their scales, and the 68-byte packet.
//! - [`adafruit`]: the library's calibration (offsets, hard iron, symmetric soft iron), its
//!   `sensor_calib.json`, how it is applied, and what it cannot carry of an imucal fit.
//! - [`gauge`]: the symmetric square root of `AᵀA` that turns imucal's triangular magnetometer
//!   matrix into the symmetric one the packet carries.
//! - [`motioncal_client`]: talking to such a board over a serial link.

pub mod adafruit;
pub mod gauge;
pub mod motioncal;
pub mod motioncal_client;

pub use adafruit::{limitations, AdafruitCalibration, AdafruitLimitations, Conversion};
pub use motioncal::{decode_packet, encode_packet, PacketError, SketchLine};
pub use motioncal_client::{EchoCheck, MotionCalClient, MotionCalError};

use thiserror::Error;

/// Why a calibration cannot be expressed in the Adafruit/MotionCal form.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CompatError {
    /// The magnetometer matrix is singular or not finite.
    #[error(
        "the magnetometer matrix is singular or not finite, so it has no symmetric form; \
         refit the magnetometer with data covering more orientations"
    )]
    DegenerateMagnetometer,
    /// A value is not a finite number.
    #[error("{0} is not a finite number; refit, the parameter file is damaged")]
    NotFinite(&'static str),
    /// The soft-iron matrix is not symmetric, so the packet cannot carry it.
    #[error(
        "the soft-iron matrix is not symmetric (|[{row}][{col}] − [{col}][{row}]| = {gap:e}); \
         the MotionCal packet carries only a symmetric matrix, build it with \
         `AdafruitCalibration::from_set`"
    )]
    NotSymmetric {
        /// Row of the offending pair.
        row: usize,
        /// Column of the offending pair.
        col: usize,
        /// Size of the asymmetry.
        gap: f32,
    },
}
