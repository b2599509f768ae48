//! Developer tasks for the imucal firmware: `cargo xtask firmware build|size|bench|qemu-test`.
//!
//! - `build`: release ELFs of the QEMU board (`firmware/boards/qemu-mps2-an386`), built with
//!   Debian's `/usr/bin/cargo` from the board directory so its `.cargo/config.toml` applies.
//!   `build --board NAME` / `size --board NAME` do the same for a hardware board
//!   (`nano33-ble-sense`), checked against that board's flash and RAM.
//! - `size`: text/data/bss of the firmware ELF, checked against 48 KiB flash and 16 KiB RAM.
//! - `bench`: instructions per sample of the calibration, counted exactly by a QEMU TCG plugin.
//! - `qemu-test`: the firmware in QEMU, driven over UART0 with the protocol and fed on UART1.
//!
//! Each exits with a non-zero status when a step fails or a target is missed.

mod bench;
mod build;
mod calibrate_e2e;
mod qemu;
mod qemu_test;
// The Nano 33 BLE Sense's timer extension depends only on core; its tests run here.
#[cfg(test)]
#[path = "../../firmware/boards/nano33-ble-sense/src/wrap.rs"]
mod nano_wrap;

use std::process::ExitCode;

const USAGE: &str =
    "usage: cargo xtask firmware <build|size|bench|qemu-test>, or <build|size> --board NAME";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["firmware", "build"] => build::build().map(|_| ()),
        ["firmware", "size"] => build::build().and_then(|elfs| build::size(&elfs.firmware)),
        ["firmware", "build", "--board", board] => build::build_board(board).map(|_| ()),
        ["firmware", "size", "--board", board] => build::size_board(board),
        ["firmware", "bench"] => build::build().and_then(|elfs| bench::bench(&elfs.bench)),
        ["firmware", "qemu-test"] => build::build().and_then(|elfs| qemu_test::run(&elfs.firmware)),
        _ => Err(format!("unknown command {:?}; {USAGE}", args.join(" "))),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}
