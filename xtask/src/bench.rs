//! `firmware bench`: exact instruction counts of the firmware's hot paths under QEMU.
//!
//! A TCG plugin (`insn_count_plugin.c`, compiled here with gcc) counts the instructions executed
//! between the bench ELF's `imucal_bench_start` and `imucal_bench_stop` markers. The bench runs
//! the regions listed in `REGIONS` for `ITERATIONS` iterations each (see the board's
//! `src/bin/bench.rs`); the empty region's count is the loop overhead and is subtracted.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::qemu;

/// Region names in the order the bench ELF runs them (must match the board's `REGIONS`).
const REGIONS: [&str; 4] = ["empty", "apply-plain", "apply-extended", "poll-streaming"];
/// Iterations per region (must match the board's `ITERATIONS`).
const ITERATIONS: u64 = 200;
/// Target for the plain `A·(x − b)` on 9 axes, instructions per sample.
const PLAIN_TARGET: u64 = 100;
/// Nominal core clock for the sample-rate figure, Hz.
const CORE_HZ: f64 = 64.0e6;

const PLUGIN_SOURCE: &str = include_str!("insn_count_plugin.c");

/// Builds the counting plugin next to the board's build output; returns the library's path.
fn build_plugin(elf: &Path) -> Result<PathBuf, String> {
    let dir = elf
        .parent()
        .ok_or("the bench ELF has no parent directory")?
        .join("insn-count-plugin");
    std::fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let source = dir.join("insn_count_plugin.c");
    let library = dir.join("libinsn_count.so");
    std::fs::write(&source, PLUGIN_SOURCE)
        .map_err(|e| format!("cannot write {}: {e}", source.display()))?;
    let status = Command::new("gcc")
        .args([
            "-O2", "-shared", "-fPIC", "-Wall", "-Wextra", "-Werror", "-o",
        ])
        .arg(&library)
        .arg(&source)
        .status()
        .map_err(|e| format!("could not run gcc to build the QEMU plugin: {e}"))?;
    if !status.success() {
        return Err(format!(
            "gcc failed to build the QEMU counting plugin ({status})"
        ));
    }
    Ok(library)
}

/// The address of `symbol` in `elf`, from `nm`.
fn symbol_address(elf: &Path, symbol: &str) -> Result<u64, String> {
    let output = Command::new("nm")
        .arg(elf)
        .output()
        .map_err(|e| format!("could not run nm: {e}"))?;
    String::from_utf8_lossy(&output.stdout)
        .lines()
        .find_map(
            |line| match line.split_whitespace().collect::<Vec<_>>().as_slice() {
                [addr, _, name] if *name == symbol => u64::from_str_radix(addr, 16).ok(),
                _ => None,
            },
        )
        .ok_or_else(|| {
            format!(
                "symbol {symbol} not found in {}; was the bench built?",
                elf.display()
            )
        })
}

/// Parses the plugin's "imucal-insns N" lines.
pub fn parse_counts(stderr: &str) -> Vec<u64> {
    stderr
        .lines()
        .filter_map(|line| line.strip_prefix("imucal-insns "))
        .filter_map(|n| n.trim().parse().ok())
        .collect()
}

/// Runs the bench ELF once under the plugin; returns the count of each region.
fn run_once(elf: &Path, plugin: &Path, start: u64, stop: u64) -> Result<Vec<u64>, String> {
    let plugin_arg = format!("{},start={start:x},stop={stop:x}", plugin.display());
    let mut cmd = qemu::command(elf);
    cmd.args(["-plugin", &plugin_arg]);
    let output = qemu::run_with_limit(cmd, Duration::from_secs(120))?;
    let stderr = output.stderr;
    if !output.success {
        let log = elf.with_extension("defmt");
        let _ = std::fs::write(&log, &output.stdout);
        return Err(format!(
            "the bench failed in QEMU ({}): {stderr}\n(its log: `defmt-print -e {} < {}`)",
            output.status,
            elf.display(),
            log.display()
        ));
    }
    let counts = parse_counts(&stderr);
    if counts.len() != REGIONS.len() {
        return Err(format!(
            "expected {} measured regions, the plugin reported {}: {stderr}",
            REGIONS.len(),
            counts.len()
        ));
    }
    Ok(counts)
}

/// Per-iteration cost of each region above the empty loop, instructions (rounded up).
pub fn per_iteration(counts: &[u64]) -> Result<Vec<u64>, String> {
    let (&empty, rest) = counts.split_first().ok_or("no measured regions")?;
    rest.iter()
        .map(|&c| {
            c.checked_sub(empty)
                .map(|d| d.div_ceil(ITERATIONS))
                .ok_or_else(|| {
                    format!(
                        "a region ({c}) counted fewer instructions than the empty loop ({empty})"
                    )
                })
        })
        .collect()
}

/// Runs the bench twice (counts must repeat exactly) and prints the figures.
pub fn bench(elf: &Path) -> Result<(), String> {
    let plugin = build_plugin(elf)?;
    let start = symbol_address(elf, "imucal_bench_start")?;
    let stop = symbol_address(elf, "imucal_bench_stop")?;
    let first = run_once(elf, &plugin, start, stop)?;
    let second = run_once(elf, &plugin, start, stop)?;
    if first != second {
        return Err(format!(
            "instruction counts differ between two runs: {first:?} vs {second:?}"
        ));
    }
    let per = per_iteration(&first)?;
    let [plain, extended, poll] = per.as_slice() else {
        return Err(format!("unexpected region count {per:?}"));
    };
    println!("instructions per sample (exact, QEMU TCG plugin; {ITERATIONS} iterations; loop overhead of {} subtracted; repeated run identical):", first[0] / ITERATIONS);
    println!("  apply, plain A(x-b) on 9 axes:          {plain:>6}   (target <= {PLAIN_TARGET})");
    println!(
        "  apply, all extended terms:              {extended:>6}   (+{} for bias-temperature cubic, scale-temperature, non-linearity, g-sensitivity)",
        extended.saturating_sub(*plain)
    );
    println!("  main loop poll() with calibrated stream: {poll:>6}   (one sample per poll, batches encoded and written)");
    let rate = CORE_HZ / *poll as f64;
    println!(
        "  sustainable sample rate at {:.0} MHz: {:.0} Hz (at 1 cycle per instruction, an upper bound; Cortex-M4 loads and FP ops take 1-2+ cycles)",
        CORE_HZ / 1e6,
        rate
    );
    if *plain > PLAIN_TARGET {
        return Err(format!(
            "the plain calibration costs {plain} instructions per sample, above the target of {PLAIN_TARGET}"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plugin_lines_are_parsed_and_other_lines_ignored() {
        let err = "imucal-insns 5815\nqemu: warning\nimucal-insns 49606\n";
        assert_eq!(parse_counts(err), vec![5815, 49606]);
    }

    #[test]
    fn per_iteration_subtracts_the_empty_loop_and_rounds_up() {
        let counts = [
            1000,
            1000 + 200 * 93,
            1000 + 200 * 150 + 1,
            1000 + 200 * 3000,
        ];
        assert_eq!(per_iteration(&counts), Ok(vec![93, 151, 3000]));
    }

    #[test]
    fn region_cheaper_than_empty_loop_is_an_error() {
        assert!(per_iteration(&[1000, 999]).is_err());
    }
}
