//! Talking to an IMU board over a serial port: port discovery ([`list_ports`]), the framed
//! request/response link with timeouts and retries ([`DeviceClient`]), samples in physical
//! units, and the calibration parameter file that is written to the board.
//!
//! A session: [`DeviceClient::open`] (or [`DeviceClient::connect`] over any `Read + Write`
//! link) pings, then exchanges `Hello`/`Welcome` and checks the protocol major version; the
//! `Welcome` (device id, sensors, scales, sample rate) stays available. Then
//! [`DeviceClient::capture_pose`], [`DeviceClient::collect_samples`],
//! [`DeviceClient::write_params_verified`] and friends drive the board.

mod board_identity;
mod client;
mod error;
mod params_binding;
pub mod params_json;
mod ports;
mod samples;

pub use client::capture::{PoseProgress, PoseRequest};
pub use client::{ClientOptions, DeviceClient, EventHandler, LinkStats, WriteReport};
pub use error::DeviceError;
pub use params_json::{ParamsFile, ParamsFileError, MOTIONCAL_SKETCH, PARAMS_FILE_FORMAT};
pub use ports::{
    choose_port, choose_port_with_reason, list_ports, open_port, BoardMatch, PortInfo, PortKind,
    UsbIds, BAUD_RATE, READ_POLL,
};
pub use samples::{raw_to_units, RecordingWriter, SampleChunk, UnitSample};
