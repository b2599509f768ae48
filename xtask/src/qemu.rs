//! Starting QEMU's mps2-an386 (Cortex-M4F) with the board firmware.

use std::io::Read;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The machine and semihosting options shared by every run; semihosting exit = QEMU exit status.
pub fn base_command() -> Command {
    let mut cmd = Command::new("qemu-system-arm");
    cmd.args([
        "-cpu",
        "cortex-m4",
        "-machine",
        "mps2-an386",
        "-display",
        "none",
    ])
    .args(["-semihosting-config", "enable=on,target=native"])
    .stdin(Stdio::null());
    cmd
}

/// A run of `elf` with UART0 on stdio and no monitor (for self-contained programs such as the bench).
pub fn command(elf: &Path) -> Command {
    let mut cmd = base_command();
    cmd.args(["-serial", "null", "-monitor", "none", "-kernel"])
        .arg(elf);
    cmd
}

/// Output of a finished run.
pub struct Finished {
    /// Exit status.
    pub success: bool,
    /// Description of the status.
    pub status: String,
    /// Standard output (the guest's semihosting output: defmt frames for `defmt-print`).
    pub stdout: Vec<u8>,
    /// Standard error (QEMU's messages, plugin output).
    pub stderr: String,
}

/// Runs `cmd` to completion, killing it after `limit` (a guest whose semihosting exit failed hangs).
pub fn run_with_limit(mut cmd: Command, limit: Duration) -> Result<Finished, String> {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| {
            format!(
                "could not start qemu-system-arm ({e}); run scripts/setup-firmware-toolchain.sh"
            )
        })?;
    let stdout = drain(child.stdout.take());
    let stderr = drain(child.stderr.take());
    let deadline = Instant::now() + limit;
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
            Ok(None) => {
                kill(&mut child);
                return Err(format!(
                    "QEMU did not finish within {} s and was stopped",
                    limit.as_secs()
                ));
            }
            Err(e) => return Err(format!("waiting for QEMU failed: {e}")),
        }
    };
    Ok(Finished {
        success: status.success(),
        status: status.to_string(),
        stdout: stdout.join().unwrap_or_default(),
        stderr: String::from_utf8_lossy(&stderr.join().unwrap_or_default()).into_owned(),
    })
}

/// Reads a pipe to its end on a thread, so a full pipe never blocks the child.
fn drain<R: Read + Send + 'static>(pipe: Option<R>) -> std::thread::JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        if let Some(mut pipe) = pipe {
            let _ = pipe.read_to_end(&mut bytes);
        }
        bytes
    })
}

/// Stops a QEMU process started by this program (by its handle, never by name).
pub fn kill(child: &mut Child) {
    let _ = child.kill();
    let _ = child.wait();
}
