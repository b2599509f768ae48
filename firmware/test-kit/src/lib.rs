//! Test doubles of an imucal board, in one place for every harness that runs the firmware core
//! off the hardware: the firmware's integration tests, the fuzz targets and the QEMU bench.
//!
//! - [`bare`]: `no_std`, allocation-free doubles for targets without a heap (the QEMU bench): an
//!   IMU producing a new sample per read, a clock stepping one period per reading, a link fed
//!   one request whose output is only counted.
//! - [`shared`] (feature `std`): doubles whose state the test shares with the device it drives
//!   (an IMU reading a sample the test sets, an in-memory serial link, a clock the test moves).
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(feature = "std")]
extern crate std;

pub mod bare;
#[cfg(feature = "std")]
pub mod shared;
