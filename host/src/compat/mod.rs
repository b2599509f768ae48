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

/// Why a file could not be turned into a calibration packet for a sketch board.
#[derive(Debug, Error)]
pub enum SketchFileError {
    /// The file could not be read.
    #[error("cannot read `{path}` ({cause}); check the path")]
    Io {
        /// The file.
        path: String,
        /// The operating system's error.
        cause: std::io::Error,
    },
    /// A packet whose signature, CRC or values fail.
    #[error("`{path}` is not a valid MotionCal calibration packet: {cause}; export it again with `imucal export PARAMS --format motioncal -o cal.bin`")]
    Packet {
        /// The file.
        path: String,
        /// Why the packet was refused.
        cause: PacketError,
    },
    /// Not a packet and not a parameter file.
    #[error(transparent)]
    Params(#[from] crate::device::ParamsFileError),
    /// A parameter file without a form the sketch can store.
    #[error("`{path}` cannot be put in a calibration packet: {cause}")]
    Compat {
        /// The file.
        path: String,
        /// Why.
        cause: CompatError,
    },
}

/// The calibration a sketch board is sent for the file at `path`: a 68-byte MotionCal packet
/// (`motioncal.bin`, `imucal export --format motioncal`) as it is, or a parameter file's part
/// the sketch can apply, with a note of what it cannot (to show the user).
pub fn sketch_calibration_of_file(
    path: &std::path::Path,
) -> Result<(AdafruitCalibration, Option<String>), SketchFileError> {
    let shown = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|cause| SketchFileError::Io {
        path: shown.clone(),
        cause,
    })?;
    if bytes.get(..2) == Some(&motioncal::PACKET_SIGNATURE[..]) {
        return decode_packet(&bytes)
            .map(|cal| (cal, None))
            .map_err(|cause| SketchFileError::Packet { path: shown, cause });
    }
    let file = crate::device::ParamsFile::load(path)?;
    let set = file.to_calibration_set(&shown)?;
    let compat = |cause| SketchFileError::Compat {
        path: shown.clone(),
        cause,
    };
    let mut conversion = AdafruitCalibration::from_set(&set).map_err(compat)?;
    if !file.fitted_sensors().contains(&"mag") {
        conversion.calibration.mag_field = adafruit::LIBRARY_DEFAULT_FIELD_UT;
    }
    let note = limitations(&set, &[]).map_err(compat)?.describe();
    Ok((conversion.calibration, (!note.is_empty()).then_some(note)))
}
