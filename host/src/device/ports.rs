//! Serial port discovery and opening: which ports exist, which look like IMU boards (by USB
//! vendor id), and opening one as a raw 115200-baud link with a short read timeout.

use std::path::Path;
use std::time::Duration;

use serialport::{SerialPort, SerialPortType};

use super::DeviceError;

/// Baud rate of the imucal link (ignored by USB CDC boards and ptys, used by real UARTs).
pub const BAUD_RATE: u32 = 115_200;

/// Read timeout of an opened port: how long one `read` waits for bytes. Short, so the client can
/// check its own deadlines often; request timeouts are enforced by the client.
pub const READ_POLL: Duration = Duration::from_millis(20);

/// USB identity of a port, where the operating system reports it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UsbIds {
    /// Vendor id.
    pub vid: u16,
    /// Product id.
    pub pid: u16,
    /// Serial number string.
    pub serial_number: Option<String>,
    /// Manufacturer string.
    pub manufacturer: Option<String>,
    /// Product string.
    pub product: Option<String>,
}

/// How a port is attached.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PortKind {
    /// A USB serial device (CDC-ACM or a USB-UART bridge).
    Usb,
    /// A PCI serial card.
    Pci,
    /// A Bluetooth serial link.
    Bluetooth,
    /// Anything else (on-board UART, pseudo-terminal, unknown).
    Other,
}

/// One serial port found on this computer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PortInfo {
    /// Path or name to open, e.g. `/dev/ttyACM0` or `COM3`.
    pub path: String,
    /// How it is attached.
    pub kind: PortKind,
    /// USB identity, for USB ports.
    pub usb: Option<UsbIds>,
}

/// USB vendors whose boards commonly carry an IMU running imucal firmware.
const BOARD_VENDORS: [(u16, &str); 6] = [
    (0x2341, "Arduino"),
    (0x1915, "Nordic Semiconductor (nRF)"),
    (0x0483, "STMicroelectronics"),
    (0x239A, "Adafruit"),
    (0x303A, "Espressif"),
    (0x2E8A, "Raspberry Pi (RP2040)"),
];

/// Boards recognised by exact USB vendor and product id.
const KNOWN_BOARDS: [(u16, u16, &str); 8] = [
    (0x1209, 0x0001, "imucal firmware (pid.codes test id)"),
    (0x2341, 0x805A, "Arduino Nano 33 BLE / BLE Sense"),
    (
        0x2341,
        0x005A,
        "Arduino Nano 33 BLE / BLE Sense (bootloader)",
    ),
    (0x2E8A, 0x0005, "Raspberry Pi Pico (MicroPython)"),
    (0x2E8A, 0x000A, "Raspberry Pi Pico (Pico SDK USB serial)"),
    (
        0x0483,
        0x374B,
        "ST-LINK/V2-1 virtual COM port (Nucleo, Discovery)",
    ),
    (0x0483, 0x5740, "STM32 USB virtual COM port"),
    (
        0x303A,
        0x1001,
        "Espressif USB JTAG/serial (ESP32-C3, -S3, -C6)",
    ),
];

/// USB-UART bridge chips: a generic adapter, often soldered onto IMU breakout boards.
const USB_SERIAL_BRIDGES: [(u16, u16, &str); 3] = [
    (0x10C4, 0xEA60, "Silicon Labs CP210x"),
    (0x1A86, 0x7523, "WCH CH340"),
    (0x0403, 0x6001, "FTDI FT232R"),
];

/// How well a port matches a board that may run imucal firmware, best first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum BoardMatch {
    /// Exact USB vendor and product id of a known board.
    Known(&'static str),
    /// The vendor makes boards with IMUs; the product is not one imucal knows.
    Vendor(&'static str),
    /// A USB-UART bridge chip (generic adapter, often on IMU breakout boards).
    Bridge(&'static str),
}

impl BoardMatch {
    /// A short phrase for listings.
    pub fn describe(self) -> String {
        match self {
            BoardMatch::Known(name) => name.to_string(),
            BoardMatch::Vendor(vendor) => format!("a {vendor} board"),
            BoardMatch::Bridge(chip) => {
                format!("USB-serial adapter, {chip} (often on IMU breakout boards)")
            }
        }
    }
}

impl PortInfo {
    /// The board vendor's name when the USB vendor id is one that commonly carries an IMU
    /// board (Arduino, nRF, STM, Adafruit, Espressif, Raspberry Pi).
    pub fn likely_board(&self) -> Option<&'static str> {
        let vid = self.usb.as_ref()?.vid;
        BOARD_VENDORS
            .iter()
            .find(|(known, _)| *known == vid)
            .map(|(_, name)| *name)
    }

    /// What this port is, by USB vendor and product id: a known board, a board vendor, or a
    /// USB-serial bridge; `None` for anything else.
    pub fn board_match(&self) -> Option<BoardMatch> {
        let usb = self.usb.as_ref()?;
        let exact = |table: &[(u16, u16, &'static str)]| {
            table
                .iter()
                .find(|(vid, pid, _)| *vid == usb.vid && *pid == usb.pid)
                .map(|(_, _, name)| *name)
        };
        exact(&KNOWN_BOARDS)
            .map(BoardMatch::Known)
            .or_else(|| self.likely_board().map(BoardMatch::Vendor))
            .or_else(|| exact(&USB_SERIAL_BRIDGES).map(BoardMatch::Bridge))
    }

    /// A one-line description: kind, USB ids, product and serial number where known.
    pub fn describe(&self) -> String {
        match (&self.kind, &self.usb) {
            (_, Some(usb)) => {
                let mut text = format!("USB {:04x}:{:04x}", usb.vid, usb.pid);
                for part in [&usb.manufacturer, &usb.product].into_iter().flatten() {
                    text.push(' ');
                    text.push_str(part);
                }
                if let Some(serial) = &usb.serial_number {
                    text.push_str(&format!(" (serial {serial})"));
                }
                text
            }
            (PortKind::Pci, None) => "PCI serial".to_string(),
            (PortKind::Bluetooth, None) => "Bluetooth serial".to_string(),
            _ => "serial".to_string(),
        }
    }
}

/// Lists the serial ports of this computer, USB ports first.
///
/// Legacy on-board UART entries of unknown type (`/dev/ttyS*` on Linux, which the kernel lists
/// whether or not hardware is behind them) are left out. Pseudo-terminals (the simulator, QEMU)
/// are never listed; give their path explicitly.
pub fn list_ports() -> Result<Vec<PortInfo>, DeviceError> {
    // serialport's sysfs scan panics when the directory is missing (some containers).
    if cfg!(target_os = "linux") && !Path::new("/sys/class/tty").is_dir() {
        return Ok(Vec::new());
    }
    let found = serialport::available_ports().map_err(|e| DeviceError::Enumerate {
        detail: e.description,
    })?;
    let mut ports: Vec<PortInfo> = found
        .into_iter()
        .map(|p| {
            let (kind, usb) = match p.port_type {
                SerialPortType::UsbPort(u) => (
                    PortKind::Usb,
                    Some(UsbIds {
                        vid: u.vid,
                        pid: u.pid,
                        serial_number: u.serial_number,
                        manufacturer: u.manufacturer,
                        product: u.product,
                    }),
                ),
                SerialPortType::PciPort => (PortKind::Pci, None),
                SerialPortType::BluetoothPort => (PortKind::Bluetooth, None),
                SerialPortType::Unknown => (PortKind::Other, None),
            };
            PortInfo {
                path: p.port_name,
                kind,
                usb,
            }
        })
        .filter(|p| !(p.kind == PortKind::Other && p.path.starts_with("/dev/ttyS")))
        .collect();
    ports.sort_by(|a, b| {
        (a.kind != PortKind::Usb, a.path.as_str()).cmp(&(b.kind != PortKind::Usb, b.path.as_str()))
    });
    Ok(ports)
}

/// The port a command uses when none is given: the only port of the best match class (known
/// board, then board vendor, then USB-serial bridge, then any USB port). Errors name the
/// candidates when there are none or several.
pub fn choose_port(ports: &[PortInfo]) -> Result<&PortInfo, DeviceError> {
    choose_port_with_reason(ports).map(|(port, _)| port)
}

/// [`choose_port`] together with the reason, as a phrase such as
/// "the only known board (Arduino Nano 33 BLE / BLE Sense)".
pub fn choose_port_with_reason(ports: &[PortInfo]) -> Result<(&PortInfo, String), DeviceError> {
    let class = |p: &PortInfo| match p.board_match() {
        Some(BoardMatch::Known(_)) => 0,
        Some(BoardMatch::Vendor(_)) => 1,
        Some(BoardMatch::Bridge(_)) => 2,
        None if p.kind == PortKind::Usb => 3,
        None => 4,
    };
    let best = ports.iter().map(class).min().filter(|c| *c < 4);
    let candidates: Vec<&PortInfo> = match best {
        Some(best) => ports.iter().filter(|p| class(p) == best).collect(),
        None => Vec::new(),
    };
    match candidates.as_slice() {
        [one] => {
            let what = match one.board_match() {
                Some(BoardMatch::Known(name)) => format!("the only known IMU board ({name})"),
                Some(BoardMatch::Vendor(vendor)) => {
                    format!("the only port from a board vendor ({vendor})")
                }
                Some(BoardMatch::Bridge(chip)) => {
                    format!("the only USB-serial adapter ({chip}) and no board was recognised")
                }
                None => "the only USB serial port".to_string(),
            };
            Ok((one, what))
        }
        [] => Err(DeviceError::NoPortChosen {
            reason: "no USB serial port found (is the board plugged in?)".to_string(),
        }),
        several => Err(DeviceError::NoPortChosen {
            reason: format!(
                "several candidate ports found ({})",
                several
                    .iter()
                    .map(|p| p.path.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }),
    }
}

/// Opens `path` as the raw link to a board, exclusively, with [`READ_POLL`] as read timeout.
///
/// On Unix the descriptor is made non-blocking: a `read` after a poll that said "ready" could
/// otherwise wait forever when another program reading the same port (`cat /dev/ttyACM0`) took
/// the bytes in between; non-blocking, it returns `WouldBlock` and the client's deadlines hold.
/// DTR is raised where the port supports it (some USB boards only send while it is set); on a
/// pseudo-terminal that call fails and is ignored.
pub fn open_port(path: &str) -> Result<Box<dyn SerialPort>, DeviceError> {
    let builder = serialport::new(path, BAUD_RATE).timeout(READ_POLL);
    #[cfg(unix)]
    let mut port = {
        let port = builder.open_native().map_err(|e| open_error(path, e))?;
        never_block(&port).map_err(|cause| DeviceError::Open {
            port: path.to_string(),
            detail: format!("cannot make the port non-blocking: {cause}"),
        })?;
        Box::new(port) as Box<dyn SerialPort>
    };
    #[cfg(not(unix))]
    let mut port = builder.open().map_err(|e| open_error(path, e))?;
    // Modem lines do not exist on a pty (ENOTTY); never fatal.
    let _ = port.write_data_terminal_ready(true);
    Ok(port)
}

/// Sets `O_NONBLOCK` on the port's descriptor (see [`open_port`]).
#[cfg(unix)]
fn never_block(port: &serialport::TTYPort) -> std::io::Result<()> {
    use nix::fcntl::{fcntl, FcntlArg, OFlag};
    use std::os::fd::AsRawFd;
    let fd = port.as_raw_fd();
    let flags = OFlag::from_bits_truncate(fcntl(fd, FcntlArg::F_GETFL)?);
    fcntl(fd, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK))?;
    Ok(())
}

/// Maps serialport's open error to a sentence for the user.
fn open_error(path: &str, error: serialport::Error) -> DeviceError {
    let port = path.to_string();
    match error.kind {
        serialport::ErrorKind::NoDevice => DeviceError::PortBusy { port },
        serialport::ErrorKind::Io(std::io::ErrorKind::NotFound) => DeviceError::NoSuchPort { port },
        serialport::ErrorKind::Io(std::io::ErrorKind::PermissionDenied) => {
            DeviceError::PermissionDenied { port }
        }
        // A missing node can surface as another errno; on Windows COM names are not paths.
        _ if !Path::new(path).exists() && cfg!(unix) => DeviceError::NoSuchPort { port },
        _ => DeviceError::Open {
            port,
            detail: error.description,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn usb_port(path: &str, vid: u16) -> PortInfo {
        usb_port_id(path, vid, 0x8036)
    }

    fn usb_port_id(path: &str, vid: u16, pid: u16) -> PortInfo {
        PortInfo {
            path: path.to_string(),
            kind: PortKind::Usb,
            usb: Some(UsbIds {
                vid,
                pid,
                serial_number: None,
                manufacturer: None,
                product: None,
            }),
        }
    }

    #[test]
    fn choose_port_prefers_the_single_known_board_vendor() {
        let ports = [
            usb_port("/dev/ttyUSB0", 0x0403),
            usb_port("/dev/ttyACM0", 0x2341),
        ];
        assert_eq!(
            choose_port(&ports).map(|p| p.path.as_str()).ok(),
            Some("/dev/ttyACM0")
        );
    }

    #[test]
    fn choose_port_refuses_to_guess_between_two_boards_and_names_both() {
        let ports = [
            usb_port("/dev/ttyACM0", 0x2341),
            usb_port("/dev/ttyACM1", 0x303A),
        ];
        let message = choose_port(&ports)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            message.contains("/dev/ttyACM0") && message.contains("/dev/ttyACM1"),
            "{message}"
        );
        assert!(message.contains("--port"), "{message}");
    }

    #[test]
    fn exact_board_ids_are_named_and_win_over_a_vendor_match_and_a_bridge() {
        let nano = usb_port_id("/dev/ttyACM1", 0x2341, 0x805A);
        assert_eq!(
            nano.board_match(),
            Some(BoardMatch::Known("Arduino Nano 33 BLE / BLE Sense"))
        );
        let ports = [
            usb_port_id("/dev/ttyUSB0", 0x10C4, 0xEA60),
            usb_port_id("/dev/ttyACM0", 0x0483, 0x1234),
            nano,
        ];
        let (port, why) = choose_port_with_reason(&ports).expect("one known board");
        assert_eq!(port.path, "/dev/ttyACM1");
        assert!(why.contains("Nano 33 BLE"), "{why}");
    }

    #[test]
    fn a_lone_usb_serial_bridge_is_chosen_and_called_an_adapter() {
        let ports = [usb_port_id("/dev/ttyUSB0", 0x1A86, 0x7523)];
        let (port, why) = choose_port_with_reason(&ports).expect("the only adapter");
        assert_eq!(port.path, "/dev/ttyUSB0");
        assert!(why.contains("CH340"), "{why}");
        let described = ports[0].board_match().map(BoardMatch::describe);
        assert_eq!(
            described.as_deref(),
            Some("USB-serial adapter, WCH CH340 (often on IMU breakout boards)")
        );
    }
}
