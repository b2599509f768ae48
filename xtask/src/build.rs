//! Building the board firmware and measuring its size.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Board crate, relative to the repository root.
pub const BOARD_DIR: &str = "firmware/boards/qemu-mps2-an386";
/// Flash budget of the release firmware (text + data), bytes.
pub const FLASH_BUDGET: u64 = 48 * 1024;
/// Static RAM budget of the release firmware (data + bss), bytes.
pub const RAM_BUDGET: u64 = 16 * 1024;

/// The release ELFs of the board.
pub struct Elfs {
    /// The firmware proper.
    pub firmware: PathBuf,
    /// The instruction-count bench.
    pub bench: PathBuf,
}

/// The repository root (this crate's parent directory).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// Where every board's release ELFs land: the boards share one target directory (their
/// `.cargo/config.toml` sets it), so `core` and the crates they share are built once.
pub fn firmware_release_dir() -> PathBuf {
    repo_root().join("firmware/boards/target/thumbv7em-none-eabihf/release")
}

/// Builds the board's release ELFs with Debian's cargo (the rustup proxy ignores build-std).
pub fn build() -> Result<Elfs, String> {
    let board = repo_root().join(BOARD_DIR);
    cargo_build_release(&board, &[])?;
    let release = firmware_release_dir();
    let elfs = Elfs {
        firmware: release.join("imucal-qemu"),
        bench: release.join("imucal-qemu-bench"),
    };
    for elf in [&elfs.firmware, &elfs.bench] {
        if !elf.exists() {
            return Err(format!(
                "the build succeeded but {} is missing",
                elf.display()
            ));
        }
    }
    Ok(elfs)
}

/// A hardware board whose firmware `--board NAME` selects (the QEMU board is the default).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Board {
    /// Name given to `--board`.
    pub name: &'static str,
    /// Board crate, relative to the repository root.
    pub dir: &'static str,
    /// Name of the firmware binary.
    pub firmware_bin: &'static str,
    /// Cargo features of the board crate that select this variant.
    pub features: &'static [&'static str],
    /// Flash available to the firmware (text + data), bytes.
    pub flash_budget: u64,
    /// Static RAM budget (data + bss), bytes.
    pub ram_budget: u64,
}

/// Hardware boards besides the QEMU one.
pub const HARDWARE_BOARDS: [Board; 2] = [
    Board {
        name: "nano33-ble-sense",
        dir: "firmware/boards/nano33-ble-sense",
        firmware_bin: "nano33-ble-sense",
        features: &[],
        // The FLASH region of its memory.x: 0x10000..0xFE000 behind the Arduino bootloader.
        flash_budget: 0xEE000,
        // 256 KiB of RAM less 64 KiB kept for the stack, where the firmware core's state lives.
        ram_budget: 192 * 1024,
    },
    // The Rev2 (BMI270 + BMM150): the same board crate with its `rev2` feature.
    Board {
        name: "nano33-ble-sense-rev2",
        dir: "firmware/boards/nano33-ble-sense",
        firmware_bin: "nano33-ble-sense",
        features: &["rev2"],
        flash_budget: 0xEE000,
        ram_budget: 192 * 1024,
    },
];

/// Name of the QEMU board for `--board`.
pub const QEMU_BOARD: &str = "qemu-mps2-an386";

/// The hardware board called `name`, or an error listing the known boards.
pub fn find_board(name: &str) -> Result<Board, String> {
    HARDWARE_BOARDS
        .iter()
        .find(|board| board.name == name)
        .copied()
        .ok_or_else(|| {
            let known: Vec<&str> = HARDWARE_BOARDS.iter().map(|b| b.name).collect();
            format!(
                "unknown board {name:?}; use {QEMU_BOARD} or one of {}",
                known.join(", ")
            )
        })
}

/// Builds the release firmware of the board called `name` and returns its ELF.
pub fn build_board(name: &str) -> Result<PathBuf, String> {
    if name == QEMU_BOARD {
        return build().map(|elfs| elfs.firmware);
    }
    let board = find_board(name)?;
    let dir = repo_root().join(board.dir);
    cargo_build_release(&dir, board.features)?;
    let elf = firmware_release_dir().join(board.firmware_bin);
    if elf.exists() {
        Ok(elf)
    } else {
        Err(format!(
            "the build succeeded but {} is missing",
            elf.display()
        ))
    }
}

/// Builds the board called `name` and prints its size against that board's budgets.
pub fn size_board(name: &str) -> Result<(), String> {
    if name == QEMU_BOARD {
        return build().and_then(|elfs| size(&elfs.firmware));
    }
    let board = find_board(name)?;
    let elf = build_board(name)?;
    size_within(&elf, board.flash_budget, board.ram_budget)
}

/// Runs `cargo build --release` in a board directory, so its `.cargo/config.toml` applies.
fn cargo_build_release(board: &Path, features: &[&str]) -> Result<(), String> {
    let cargo = Path::new("/usr/bin/cargo");
    if !cargo.exists() {
        return Err("/usr/bin/cargo not found; run scripts/setup-firmware-toolchain.sh".into());
    }
    println!("building release firmware in {}", board.display());
    let mut command = Command::new(cargo);
    command.args(["build", "--release"]);
    if !features.is_empty() {
        command.args(["--features", &features.join(",")]);
    }
    let status = command
        .current_dir(board)
        // The outer `cargo xtask` exports its own toolchain settings; the board uses its own.
        .env_remove("RUSTC")
        .env_remove("RUSTUP_TOOLCHAIN")
        .env_remove("CARGO_TARGET_DIR")
        .env_remove("RUSTFLAGS")
        .status()
        .map_err(|e| format!("could not start /usr/bin/cargo: {e}"))?;
    if !status.success() {
        return Err(format!(
            "the firmware build failed ({status}); see the compiler output above"
        ));
    }
    Ok(())
}

/// Section sizes in the Berkeley sense: text (code + read-only data), data, bss (incl. no-init).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sizes {
    /// Code and constants, bytes (in flash).
    pub text: u64,
    /// Initialised data, bytes (in flash and in RAM).
    pub data: u64,
    /// Zeroed and no-init data, bytes (in RAM).
    pub bss: u64,
}

/// Parses the output of `size ELF` (Berkeley format: a header line, then text data bss ...).
pub fn parse_size_output(output: &str) -> Result<Sizes, String> {
    let line = output
        .lines()
        .nth(1)
        .ok_or_else(|| format!("unexpected `size` output: {output:?}"))?;
    let fields: Vec<u64> = line
        .split_whitespace()
        .take(3)
        .map(str::parse)
        .collect::<Result<_, _>>()
        .map_err(|e| format!("unexpected `size` output {line:?}: {e}"))?;
    match fields.as_slice() {
        [text, data, bss] => Ok(Sizes {
            text: *text,
            data: *data,
            bss: *bss,
        }),
        _ => Err(format!("unexpected `size` output {line:?}")),
    }
}

/// Prints the QEMU firmware's flash and RAM use and checks them against its budgets.
pub fn size(elf: &Path) -> Result<(), String> {
    size_within(elf, FLASH_BUDGET, RAM_BUDGET)
}

/// Prints a firmware's flash and RAM use and checks them against the given budgets, bytes.
pub fn size_within(elf: &Path, flash_budget: u64, ram_budget: u64) -> Result<(), String> {
    let output = Command::new("size")
        .arg(elf)
        .output()
        .map_err(|e| format!("could not run `size` (binutils): {e}"))?;
    if !output.status.success() {
        return Err(format!(
            "`size {}` failed: {}",
            elf.display(),
            String::from_utf8_lossy(&output.stderr)
        ));
    }
    let sizes = parse_size_output(&String::from_utf8_lossy(&output.stdout))?;
    let flash = sizes.text + sizes.data;
    let ram = sizes.data + sizes.bss;
    println!("firmware {}", elf.display());
    println!(
        "  text {:>7} B   data {:>5} B   bss {:>6} B",
        sizes.text, sizes.data, sizes.bss
    );
    println!(
        "  flash {flash:>6} B ({:.1} KiB of {} KiB)   static RAM {ram:>6} B ({:.1} KiB of {} KiB; stack not included)",
        flash as f64 / 1024.0,
        flash_budget / 1024,
        ram as f64 / 1024.0,
        ram_budget / 1024
    );
    let mut over = Vec::new();
    if flash > flash_budget {
        over.push(format!("flash {flash} B exceeds {flash_budget} B"));
    }
    if ram > ram_budget {
        over.push(format!("static RAM {ram} B exceeds {ram_budget} B"));
    }
    if over.is_empty() {
        println!("  within budget");
        Ok(())
    } else {
        Err(format!(
            "{}; see `nm -S --size-sort -C` for the largest symbols",
            over.join(", ")
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn berkeley_size_output_is_parsed_into_text_data_bss() {
        let out = "   text\t   data\t    bss\t    dec\t    hex\tfilename\n  39856\t      4\t   2072\t  41932\t   a3cc\tfw\n";
        assert_eq!(
            parse_size_output(out),
            Ok(Sizes {
                text: 39856,
                data: 4,
                bss: 2072
            })
        );
    }

    #[test]
    fn board_names_select_their_crate_and_unknown_names_list_the_choices() {
        let nano = find_board("nano33-ble-sense").expect("a known board");
        assert_eq!(nano.dir, "firmware/boards/nano33-ble-sense");
        assert!(repo_root().join(nano.dir).join("Cargo.toml").exists());
        let error = find_board("nano33").expect_err("not a board name");
        assert!(error.contains("nano33-ble-sense") && error.contains(QEMU_BOARD));
    }

    #[test]
    fn malformed_size_output_is_an_error() {
        assert!(parse_size_output("text data bss\n").is_err());
        assert!(parse_size_output("h\nx y z\n").is_err());
    }
}
