//! Puts the memory layout on the linker search path as `memory.x` (`memory-bootloader.x`, or
//! `memory-no-bootloader.x` with the `no-bootloader` feature) and selects the cortex-m-rt and defmt
//! linker scripts. There is deliberately no `memory.x` in this directory: the linker looks in its
//! working directory (here) before the search path, so such a file would always win.

use std::{env, fs, path::PathBuf};

fn main() {
    let layout = if env::var_os("CARGO_FEATURE_NO_BOOTLOADER").is_some() {
        "memory-no-bootloader.x"
    } else {
        "memory-bootloader.x"
    };
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR for build scripts"));
    fs::copy(layout, out.join("memory.x")).expect("the memory layouts are next to build.rs");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory-bootloader.x");
    println!("cargo:rerun-if-changed=memory-no-bootloader.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
