//! Board support for imucal on the Arm MPS2 AN386 (Cortex-M4F) as emulated by QEMU.
//!
//! - UART0 ([`uart`]): the host link, the same protocol as on any imucal board.
//! - UART1 ([`sensor`]): sensor samples from the simulator's world and sensor physics, as
//!   `imucal_protocol::feed` frames, presented to the firmware core through its `Imu` trait, with
//!   the clock taken from the feed.
//! - [`ram_flash`]: parameter storage in RAM that survives a soft reset (real boards use flash).
//!
//! `unsafe` is confined to register access in [`uart`], the retained RAM region in
//! [`ram_flash`], and the reset helpers here, each with its justification.
#![no_std]
#![deny(unsafe_op_in_unsafe_fn)]
#![warn(missing_docs)]

pub mod ram_flash;
pub mod sensor;
pub mod uart;

/// Baud rate set on both UARTs; QEMU moves bytes as fast as the host allows whatever the rate.
pub const BAUD: u32 = 115_200;

/// Ends the program under QEMU with a success or failure exit status (semihosting).
pub fn exit(success: bool) -> ! {
    let status = if success {
        cortex_m_semihosting::debug::EXIT_SUCCESS
    } else {
        cortex_m_semihosting::debug::EXIT_FAILURE
    };
    cortex_m_semihosting::debug::exit(status);
    // Only reached when the debugger ignores the exit request.
    loop {
        cortex_m::asm::wfi();
    }
}
